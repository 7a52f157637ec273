"""One OpenGL context per process, shared by every camera of every episode it renders.

``mujoco.Renderer`` makes an OpenGL (EGL) context and uploads the model (meshes, textures, shadow and
multisample buffers) each time one is made: two per episode cost 0.65 s on llvmpipe. Here the
process makes one context, on first use, and one MuJoCo render context (``MjrContext``) per compiled
model, shared by the copies episodes of the same house run on (:data:`_MODEL_SLOTS` models kept).
RGB, depth and segmentation frames of any camera come from the same context, each read back once
with ``mjr_readPixels`` into the caller's frame.
"""

from __future__ import annotations

import atexit
import os
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Protocol

import mujoco
import numpy as np

from molmo_lerobot.gl import gl_error

#: render contexts kept per process (as many as the compiled-model cache holds, :mod:`molmo_lerobot.sim.env`)
_MODEL_SLOTS = 4
#: the process's GL context and render contexts, keyed by process id (a forked child makes its own)
_PROCESS_RENDERERS: dict[int, FrameRenderer] = {}


class GLContext(Protocol):
    """MuJoCo's GL context of a backend (``mujoco.egl.GLContext``, …)."""

    def make_current(self) -> None: ...
    def free(self) -> None: ...


@dataclass
class _Slot:
    model: mujoco.MjModel  # the compiled model the context was made from (kept alive: its id is the key)
    context: mujoco.MjrContext
    scene: mujoco.MjvScene


@dataclass
class FrameRenderer:
    """The process's GL context and a render context per compiled model (module docstring)."""

    gl: GLContext
    slots: OrderedDict[int, _Slot] = field(default_factory=OrderedDict)
    #: seconds spent making the GL context and render contexts
    setup_s: float = 0.0

    def _slot(self, source: mujoco.MjModel) -> _Slot:
        key = id(source)
        slot = self.slots.get(key)
        if slot is not None and slot.model is source:
            self.slots.move_to_end(key)
            return slot
        t0 = time.perf_counter()
        try:  # a backend whose context creation "succeeded" without a display (GLFW) fails here
            self.gl.make_current()
            context = mujoco.MjrContext(source, mujoco.mjtFontScale.mjFONTSCALE_150.value)
        except (mujoco.FatalError, RuntimeError) as exc:
            raise gl_error(exc) from None
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, context)
        context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        slot = _Slot(source, context, mujoco.MjvScene(source, maxgeom=10000))
        self.slots[key] = slot
        while len(self.slots) > _MODEL_SLOTS:
            self.slots.popitem(last=False)[1].context.free()
        self.setup_s += time.perf_counter() - t0
        return slot

    def _draw(self, source: mujoco.MjModel, model: mujoco.MjModel, data: mujoco.MjData, camera: int,
              option: mujoco.MjvOption, size: tuple[int, int], segment: bool = False) -> tuple[_Slot, mujoco.MjrRect]:
        slot = self._slot(source)
        self.gl.make_current()

        # bind this model's offscreen buffers: the last frame may have been another model's
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, slot.context)
        cam = mujoco.MjvCamera()
        cam.type, cam.fixedcamid = mujoco.mjtCamera.mjCAMERA_FIXED, camera
        mujoco.mjv_updateScene(model, data, option, None, cam, mujoco.mjtCatBit.mjCAT_ALL.value, slot.scene)
        slot.scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = segment
        slot.scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = segment
        rect = mujoco.MjrRect(0, 0, size[0], size[1])
        mujoco.mjr_render(rect, slot.scene, slot.context)
        return slot, rect

    def rgb(self, source: mujoco.MjModel, model: mujoco.MjModel, data: mujoco.MjData, camera: int,
            option: mujoco.MjvOption, size: tuple[int, int]) -> np.ndarray:
        """An RGB uint8 frame (H, W, 3) of ``camera`` (``size``: width, height)."""
        slot, rect = self._draw(source, model, data, camera, option, size)
        out = np.empty((size[1], size[0], 3), dtype=np.uint8)
        mujoco.mjr_readPixels(out, None, rect, slot.context)
        return np.ascontiguousarray(out[::-1])  # OpenGL's rows run bottom-up

    def depth(self, source: mujoco.MjModel, model: mujoco.MjModel, data: mujoco.MjData, camera: int,
              option: mujoco.MjvOption, size: tuple[int, int]) -> np.ndarray:
        """Depth in metres, float32 (H, W): drawn and converted as ``mujoco.Renderer`` does (segmentation
        colours, which leave the depth buffer unresolved by multisampling)."""
        slot, rect = self._draw(source, model, data, camera, option, size, segment=True)
        raw = np.empty((size[1], size[0]), dtype=np.float32)
        mujoco.mjr_readPixels(None, raw, rect, slot.context)
        slot.scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = False
        slot.scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = False
        extent = model.stat.extent
        near, far = np.float32(model.vis.map.znear * extent), np.float32(model.vis.map.zfar * extent)
        c = np.float32(-0.5) * (-(far + near) / (far - near)) - np.float32(0.5)
        d = np.float32(-0.5) * (-(np.float32(2) * far * near) / (far - near))
        return (d / (raw[::-1].astype(np.float64) + c)).astype(np.float32)

    def geom_ids(self, source: mujoco.MjModel, model: mujoco.MjModel, data: mujoco.MjData, camera: int,
                 option: mujoco.MjvOption, size: tuple[int, int]) -> np.ndarray:
        """Per pixel, the id of the geom drawn there, -1 where none is (H, W)."""
        slot, rect = self._draw(source, model, data, camera, option, size, segment=True)
        out = np.empty((size[1], size[0], 3), dtype=np.uint8)
        mujoco.mjr_readPixels(out, None, rect, slot.context)
        slot.scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = False
        slot.scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = False
        image = out[::-1].astype(np.uint32)
        segid = image[..., 0] + (image[..., 1] << 8) + (image[..., 2] << 16)  # 0: background, else segid + 1
        lookup = np.full(slot.scene.ngeom + 1, -1, dtype=np.int64)
        for geom in slot.scene.geoms[:slot.scene.ngeom]:
            if geom.segid != -1 and geom.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                lookup[geom.segid + 1] = geom.objid
        return lookup[np.minimum(segid, slot.scene.ngeom)]


def process_renderer() -> FrameRenderer:
    """This process's :class:`FrameRenderer`, its GL context made on first use."""
    pid = os.getpid()
    renderer = _PROCESS_RENDERERS.get(pid)
    if renderer is None:
        _PROCESS_RENDERERS.clear()  # a forked child never uses its parent's context
        t0 = time.perf_counter()
        try:
            gl = mujoco.GLContext(64, 64)
            gl.make_current()
        except (mujoco.FatalError, RuntimeError, ImportError, AttributeError) as exc:
            raise gl_error(exc) from None  # one line: the backend MuJoCo used and what to set
        renderer = FrameRenderer(gl, setup_s=time.perf_counter() - t0)
        _PROCESS_RENDERERS[pid] = renderer
        atexit.register(_release, pid)
    return renderer


def _release(pid: int) -> None:
    """Free the render contexts, then the GL context, while EGL is still up (at interpreter exit)."""
    renderer = _PROCESS_RENDERERS.pop(pid, None)
    if renderer is None or pid != os.getpid():
        return
    renderer.gl.make_current()
    for slot in renderer.slots.values():
        slot.context.free()
    renderer.slots.clear()
    renderer.gl.free()
