"""LIBERO's env server: run with the LIBERO venv's Python (``python -m molmo_lerobot.suites.libero_server``),
spoken to through :mod:`~molmo_lerobot.suites.pipe` by :class:`~molmo_lerobot.suites.libero.LiberoSuite`.

It builds LIBERO's own ``OffScreenRenderEnv`` from the task's BDDL file and plays an episode the way
LeRobot's ``LiberoEnv`` does (``lerobot-eval --env.type=libero``): reset with the episode's seed, set the
task's init state, settle for :data:`SETTLE_STEPS` no-op steps, then delta end-effector control; a step
succeeds when LIBERO's goal predicates hold, and the episode terminates then. Observations follow LeRobot's
LIBERO datasets: ``observation.images.image`` (agent view) and ``observation.images.image2`` (wrist), each
turned 180° (LIBERO renders them upside down), and an 8-D ``observation.state``: end-effector position,
its orientation as an axis-angle, the two gripper finger positions.

One env per task is kept and reset per episode; with ``hard_reset`` (LeRobot's default) LIBERO rebuilds
the model at every reset, without it it reuses the compiled model. A reset is cheaper here than in LeRobot and
gives the same bits: the rebuild reuses what comes out the same every time (:class:`RebuildCache`), and the
frames of a reset that no policy sees are not drawn (:func:`unseen_frames`). A step draws its frames only when
asked (``images``): the harness asks when the policy or a recorder will read them, so a policy whose chunks run
open loop, or one that reads no images, costs no drawing at the steps in between.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from types import SimpleNamespace
from typing import Any

import numpy as np

from molmo_lerobot.suites.pipe import serve_env_server

#: no-op steps after setting the init state, so that objects settle (LeRobot's ``num_steps_wait``)
SETTLE_STEPS = 10
#: the no-op action: no motion, gripper open
NOOP = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0)
#: LIBERO's camera observation → LeRobot's LIBERO dataset feature
CAMERAS = {"agentview_image": "observation.images.image", "robot0_eye_in_hand_image": "observation.images.image2"}
CONTROL_FREQ = 20


def axis_angle(quat_xyzw: np.ndarray) -> np.ndarray:
    """A unit quaternion (x, y, z, w) as a rotation vector (axis × angle), zero for the identity. In float32
    with torch's kernels, as LeRobot computes it for ``lerobot-eval``: numpy's float32 ``arccos`` differs from
    torch's in the last bit for about a third of all angles, and a policy should see the same bits."""
    import torch

    q = torch.as_tensor(np.asarray(quat_xyzw), dtype=torch.float32)
    w = q[3].clamp(-1.0, 1.0)
    sin_half = torch.sqrt(torch.clamp(1.0 - w * w, min=0.0))
    if not sin_half > 1e-10:
        return np.zeros(3, dtype=np.float32)
    return ((q[:3] / sin_half) * (2.0 * torch.acos(w))).numpy()


@contextmanager
def unseen_frames() -> Iterator[None]:
    """Camera frames asked for inside are blank instead of drawn: for the frames of a reset that LeRobot's
    ``LiberoEnv`` draws and throws away (the reset's own observation, the init state's, the first settle steps').
    Drawing reads the sim and writes only GL buffers, the render context's scene and the frame itself, and the
    camera sensors are still called, so the sim, every random draw and the observables' sampling clocks are as
    with the frames drawn. At 360² on this CPU a frame is ~0.1 s, a step without frames ~0.012 s. The server's
    env asks for RGB frames only (no depth, no segmentation)."""
    from robosuite.utils.binding_utils import MjSim

    def blank(sim: Any, width: int, height: int, **_: Any) -> np.ndarray:
        return np.zeros((height, width, 3), dtype=np.uint8)

    drawn = MjSim.render
    MjSim.render = blank
    try:
        yield
    finally:
        MjSim.render = drawn


class RebuildCache:
    """The two costly pieces of robosuite's hard reset that come out the same at every reset of a task, kept.

    A hard reset (``hard_reset=True``) frees the sim and its render context, rebuilds the task's MJCF, compiles
    it into a new ``MjModel`` and makes a new render context: an EGL context and a ``MjrContext`` holding the
    model's textures and meshes uploaded for drawing (~1.3 s of the ~2.5 s reset at 360² here). Everything else
    of the reset (building the MJCF, the seeded placement sampling, observables) still runs as robosuite runs it,
    so every random draw happens as in a real hard reset. While :meth:`hooked` is active:

    - compiling an MJCF text equal to the last one compiled gives a copy of that compiled model, taken before
      anything used it (robosuite writes into its model: fixture placements, site colours), with a new
      ``MjData``. MuJoCo's compiler is deterministic and a copy holds the same bytes, so the sim is the one a
      compile would give; a different text (another task) is compiled and replaces the kept model.
    - the new sim's render context is the kept one's GL context and ``MjrContext``, which were made from a
      copy of the same model at the same point of a reset; the scene, camera and options are new, and the sim
      is forwarded when it is attached, as a new context does. Kept only while its offscreen buffer has the size
      a new one would have (robosuite enlarges it, and writes the model, for images larger than 640 × 480).
    """

    def __init__(self) -> None:
        self._xml: str | None = None
        self._model: Any = None  # the MjModel compiled from _xml, never given to a sim
        self._context: Any = None  # the render context made over a copy of _model

    @contextmanager
    def hooked(self) -> Iterator[None]:
        """Route robosuite's sim and render-context construction (``robosuite.environments.base``) through here."""
        import robosuite.environments.base as base

        saved = base.MjSim, base.MjRenderContextOffscreen
        base.MjSim = SimpleNamespace(from_xml_string=self._sim)
        base.MjRenderContextOffscreen = self._render_context
        try:
            yield
        finally:
            base.MjSim, base.MjRenderContextOffscreen = saved

    def _sim(self, xml: str) -> Any:
        import mujoco
        from robosuite.utils.binding_utils import MjSim

        if xml != self._xml:
            self.release()
            self._model, self._xml = mujoco.MjModel.from_xml_string(xml), xml
        return MjSim(copy.copy(self._model))

    def _render_context(self, sim: Any, device_id: int) -> Any:
        import mujoco
        from robosuite.utils.binding_utils import MjRenderContextOffscreen

        ctx, size = self._context, (sim.model.vis.global_.offwidth, sim.model.vis.global_.offheight)
        if ctx is None or (ctx.con.offWidth, ctx.con.offHeight) != size:
            self._context = MjRenderContextOffscreen(sim, device_id=device_id)
            return self._context
        ctx.gl_ctx.make_current()
        sim.forward()
        sim.add_render_context(ctx)
        ctx.sim, ctx.model, ctx.data = sim, sim.model, sim.data
        ctx.scn = mujoco.MjvScene(sim.model._model, maxgeom=1000)
        ctx.cam = mujoco.MjvCamera()
        ctx.cam.type, ctx.cam.fixedcamid = mujoco.mjtCamera.mjCAMERA_FIXED, 0
        ctx.vopt, ctx.pert = mujoco.MjvOption(), mujoco.MjvPerturb()
        ctx.pert.active, ctx.pert.select, ctx.pert.skinselect = 0, 0, -1
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, ctx.con)
        return ctx

    def release(self) -> None:
        """Drop the kept model and render context (the GL resources are freed with the context)."""
        self._xml = self._model = self._context = None


class LiberoServer:
    """The request handlers; state: the LIBERO benchmark objects, one env per task, the current episode."""

    def __init__(self) -> None:
        config = os.environ.get("LIBERO_CONFIG_PATH")
        if config is None:
            raise SystemExit("libero_server: LIBERO_CONFIG_PATH is not set (LiberoSuite sets it)")
        if not os.path.isfile(os.path.join(config, "config.yaml")):  # LIBERO's import would ask on stdin
            raise SystemExit(f"libero_server: no LIBERO config at {config}/config.yaml")
        from libero.libero import benchmark

        self._benchmarks = benchmark.get_benchmark_dict()
        self._suites: dict[str, Any] = {}
        self._envs: dict[tuple, Any] = {}
        self._env = None
        self._rebuilds = RebuildCache()

    def _suite(self, suite: str) -> Any:
        if suite not in self._suites:
            if suite not in self._benchmarks:
                raise ValueError(f"unknown LIBERO suite {suite!r} (known: {', '.join(sorted(self._benchmarks))})")
            self._suites[suite] = self._benchmarks[suite]()
        return self._suites[suite]

    def tasks(self, suite: str) -> dict[str, Any]:
        """The suite's tasks: name, instruction, BDDL file and number of init states."""
        s = self._suite(suite)
        out = []
        for i in range(s.get_num_tasks()):
            task = s.get_task(i)
            out.append({"task_id": i, "name": task.name, "instruction": task.language,
                        "bddl_file": f"{task.problem_folder}/{task.bddl_file}",
                        "init_states": len(s.get_task_init_states(i))})
        return {"suite": suite, "tasks": out}

    def reset(self, suite: str, task_id: int, init_state_index: int, seed: int, width: int, height: int,
              hard_reset: bool = True) -> dict[str, Any]:
        """Start an episode; its first observation."""
        from libero.libero import get_libero_path
        from libero.libero.envs import OffScreenRenderEnv

        s = self._suite(suite)
        key = (suite, task_id, width, height, hard_reset)
        env = self._envs.get(key)
        if env is None:
            self.close_envs()  # one live env (one GL context) per process
            task = s.get_task(task_id)
            with self._rebuilds.hooked(), unseen_frames():
                env = OffScreenRenderEnv(bddl_file_name=os.path.join(get_libero_path("bddl_files"),
                                                                     task.problem_folder, task.bddl_file),
                                         camera_heights=height, camera_widths=width, control_freq=CONTROL_FREQ,
                                         hard_reset=hard_reset)
                env.reset()
            self._envs[key] = env
        states = s.get_task_init_states(task_id)
        env.seed(seed)
        with self._rebuilds.hooked(), unseen_frames():
            env.reset()
            env.set_init_state(states[init_state_index % len(states)])
            for _ in range(SETTLE_STEPS - 1):
                env.step(list(NOOP))
        raw, _, _, _ = env.step(list(NOOP))  # the last settle step's frames are the policy's first
        for robot in env.robots:
            robot.controller.use_delta = True
        self._env = env
        return {"observation": self._observation(raw)}

    def step(self, action: Any, images: bool = True) -> dict[str, Any]:
        """One control step: the new observation, reward, success and termination. Without ``images`` the
        step's frames are not drawn (:func:`unseen_frames`) and the observation has the state only."""
        if self._env is None:
            raise RuntimeError("step before reset")
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (7,):
            raise ValueError(f"action: expected shape (7,), got {action.shape}")
        with nullcontext() if images else unseen_frames():
            raw, reward, done, _ = self._env.step(action)
        success = bool(self._env.check_success())
        return {"observation": self._observation(raw, images), "reward": float(reward), "success": success,
                "terminated": bool(done) or success}

    @staticmethod
    def _observation(raw: dict[str, Any], images: bool = True) -> dict[str, Any]:
        obs = {key: np.ascontiguousarray(raw[cam][::-1, ::-1]) for cam, key in CAMERAS.items()} if images else {}
        obs["observation.state"] = np.concatenate([raw["robot0_eef_pos"], axis_angle(raw["robot0_eef_quat"]),
                                                   raw["robot0_gripper_qpos"]]).astype(np.float32)
        return obs

    def close_envs(self) -> dict[str, Any]:
        for env in self._envs.values():
            env.close()
        self._envs.clear()
        self._env = None
        self._rebuilds.release()
        return {"ok": True}


def main() -> None:
    serve_env_server(LiberoServer)


if __name__ == "__main__":
    main()
