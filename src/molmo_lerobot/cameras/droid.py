"""DROID camera systems for ``franka_droid`` (a camera plugin), as MolmoSpaces places them.

``FrankaDroidCameraSystem`` (alias ``droid``): fixed cameras, no noise —

* ``wrist_camera``: the robot's own ``gripper/wrist_camera`` (on ``gripper/base``), fov 56.74°;
* ``exo_camera_1``: DROID's left shoulder camera, fixed to ``fr3_link0`` at
  ``[0.1, 0.57, 0.66]``, fov 71° (MolmoSpaces' placement);
* ``exo_camera_2``: the right shoulder camera, its mirror image in the x-z plane
  (MolmoSpaces keeps a right shoulder camera commented out; DROID has both).

``FrankaRandomizedDroidCameraSystem`` (alias ``droid_randomized``): MolmoSpaces' randomized
variant — the wrist camera with fov noise ±4°, position noise (±15/±5/±10 mm in the camera
frame) and orientation noise (±8°/±4°/±4° about x/y/z), and two exocentric cameras looking at
the workspace centre (the task's target object) from a distance of 0.2–0.8 m, 0.05–0.6 m above
it, any azimuth, fov 64–72°, look-at point jittered ±0.1 m. Every draw comes from a generator
seeded by the episode's content, so an episode always gets the same cameras, on any worker.
MolmoSpaces also re-draws exocentric placements until the target is visible (rendered
visibility); we do not render at build time, so a drawn camera may be occluded.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable, Sequence
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from molmo_lerobot import hookimpl
from molmo_lerobot.cameras.base import CameraSystem, episode_rng, look_rotation, mat_to_quat

WRIST_MJCF_NAME = "gripper/wrist_camera"
ARM_ROOT = "fr3_link0"
LEFT_SHOULDER = ((0.1, 0.57, 0.66), (-0.3633, -0.1241, 0.4263, 0.8191))


def _mirrored(offset: Sequence[float], quat: Sequence[float]) -> tuple[tuple[float, ...], list[float]]:
    """The same camera mirrored in the base's x-z plane (left shoulder -> right shoulder)."""
    rot = Rotation.from_quat(np.asarray(quat, dtype=np.float64), scalar_first=True).as_matrix()
    flip = np.array([1.0, -1.0, 1.0])
    forward, up = -rot[:, 2] * flip, rot[:, 1] * flip
    return tuple(np.asarray(offset) * flip), mat_to_quat(look_rotation(forward, up))


#: (name, offset in fr3_link0's frame, wxyz camera quaternion in that frame, fov)
SHOULDER_CAMERAS = (
    ("exo_camera_1", *LEFT_SHOULDER, 71.0),
    ("exo_camera_2", *_mirrored(*LEFT_SHOULDER), 71.0),
)
FIXED_WRIST_FOV = 56.74
RANDOM_WRIST_FOV, RANDOM_WRIST_FOV_NOISE = 52.0, (-4.0, 4.0)
RANDOM_WRIST_POS_NOISE = ((-0.015, -0.005, -0.01), (0.015, 0.005, 0.01))
RANDOM_WRIST_ROT_NOISE_DEG = (8.0, 4.0, 4.0)
EXO_DISTANCE, EXO_HEIGHT, EXO_AZIMUTH, EXO_FOV, EXO_LOOKAT_NOISE = (0.2, 0.8), (0.05, 0.6), (0.0, 2 * math.pi), \
    (64.0, 72.0), (-0.1, 0.1)


def _wrist_mount(world: mujoco.MjSpec) -> mujoco.MjsCamera:
    found = [c for c in world.cameras if c.name == WRIST_MJCF_NAME or c.name.endswith("/" + WRIST_MJCF_NAME)]
    if len(found) != 1:
        raise ValueError(f"camera system: the robot has no (unique) {WRIST_MJCF_NAME!r} camera; "
                         "DROID camera systems need franka_droid")
    return found[0]


def _arm_root(find_body: Callable[[str], mujoco.MjsBody | None]) -> mujoco.MjsBody:
    body = find_body(ARM_ROOT)
    if body is None:
        raise ValueError(f"camera system: no body {ARM_ROOT!r} (DROID camera systems need franka_droid)")
    return body


def _add_wrist(world: mujoco.MjSpec, pos: Sequence[float], quat: Sequence[float], fov: float) -> None:
    mount = _wrist_mount(world)
    mount.parent.add_camera(name="wrist_camera", pos=list(pos), quat=list(quat), fovy=float(fov))


class FrankaDroidCameraSystem(CameraSystem):
    """Wrist camera + both DROID shoulder cameras, fixed (module docstring)."""

    name = "FrankaDroidCameraSystem"
    aliases = ("droid",)

    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None], episode: Any = None) -> list[str]:
        mount = _wrist_mount(world)
        _add_wrist(world, mount.pos, mount.quat, FIXED_WRIST_FOV)
        root = _arm_root(find_body)
        for name, offset, quat, fov in SHOULDER_CAMERAS:
            root.add_camera(name=name, pos=list(offset), quat=list(quat), fovy=fov)
        return ["wrist_camera"] + [c[0] for c in SHOULDER_CAMERAS]


def workspace_centre(world: mujoco.MjSpec, episode: Any, find_body: Callable[[str], mujoco.MjsBody | None]) \
        -> np.ndarray:
    """Where the randomized exocentric cameras look: the task's target object (its episode pose,
    else its body position), else 0.5 m in front of the robot base."""
    task = episode.task
    name = getattr(task, "pickup_obj_name", None)
    poses = episode.scene_modifications.object_poses
    if name and name in poses:
        return np.asarray(poses[name][:3], dtype=np.float64)
    body = find_body(name) if name else None
    if body is not None and body.parent is not None and body.parent.name == "world":
        return np.asarray(body.pos, dtype=np.float64)
    base = np.asarray(task.robot_base_pose, dtype=np.float64)
    forward = Rotation.from_quat(base[3:], scalar_first=True).apply([0.5, 0.0, 0.0])
    return base[:3] + forward + [0.0, 0.0, 0.2]


class FrankaRandomizedDroidCameraSystem(CameraSystem):
    """Wrist camera with noise + two randomized exocentric cameras, seeded by the episode (module docstring)."""

    name = "FrankaRandomizedDroidCameraSystem"
    aliases = ("droid_randomized",)

    def episode_key(self, episode: Any) -> str:
        data = episode.model_dump(mode="json")
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()

    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None], episode: Any = None) -> list[str]:
        if episode is None:
            raise ValueError(f"{self.name} needs the episode (its randomization is seeded by it)")
        rng = episode_rng(episode)
        mount = _wrist_mount(world)
        fov = RANDOM_WRIST_FOV + rng.uniform(*RANDOM_WRIST_FOV_NOISE)
        rot = Rotation.from_quat(np.asarray(mount.quat, dtype=np.float64), scalar_first=True)
        pos = np.asarray(mount.pos, dtype=np.float64) + rot.apply(rng.uniform(*RANDOM_WRIST_POS_NOISE, size=3))
        limit = np.asarray(RANDOM_WRIST_ROT_NOISE_DEG)
        rot = rot * Rotation.from_euler("xyz", rng.uniform(-limit, limit, size=3), degrees=True)
        _add_wrist(world, pos, rot.as_quat(scalar_first=True), fov)
        centre = workspace_centre(world, episode, find_body)
        names = ["wrist_camera"]
        for k in (1, 2):
            distance, azimuth = rng.uniform(*EXO_DISTANCE), rng.uniform(*EXO_AZIMUTH)
            height, exo_fov = rng.uniform(*EXO_HEIGHT), rng.uniform(*EXO_FOV)
            lookat = centre + rng.uniform(*EXO_LOOKAT_NOISE, size=3)
            cam_pos = centre + [distance * math.cos(azimuth), distance * math.sin(azimuth), height]
            quat = mat_to_quat(look_rotation(lookat - cam_pos, (0.0, 0.0, 1.0)))
            world.worldbody.add_camera(name=f"exo_camera_{k}", pos=cam_pos.tolist(), quat=quat, fovy=float(exo_fov))
            names.append(f"exo_camera_{k}")
        return names


@hookimpl
def molmo_camera_systems() -> list[CameraSystem]:
    return [FrankaDroidCameraSystem(), FrankaRandomizedDroidCameraSystem()]
