"""Where cameras go on the Franka of ``franka_droid``, shared by its camera systems
(:mod:`~molmo_lerobot.cameras.droid`, :mod:`~molmo_lerobot.cameras.franka_eval`): the wrist mount,
the arm root and DROID's shoulder camera, mount noise, and exocentric placement until the task's
objects are seen."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from molmo_lerobot.poses import Vector

WRIST_MJCF_NAME = "gripper/wrist_camera"
ARM_ROOT = "fr3_link0"
#: DROID's shoulder camera: offset and wxyz quaternion in fr3_link0's frame, fov
EXO_CAMERA_1 = ((0.1, 0.57, 0.66), (-0.3633, -0.1241, 0.4263, 0.8191), 71.0)

@dataclass(frozen=True)
class MountNoise:
    """Noise of a camera on its mount: fov (deg, added), position (m, per axis of the camera's
    frame) and orientation (deg, ± per x/y/z Euler angle, applied in the camera's frame)."""

    fov: tuple[float, float]
    pos: tuple[tuple[float, float, float], tuple[float, float, float]]
    rot_deg: tuple[float, float, float]


#: the least fraction of an exocentric camera's pixels each task object and the gripper must cover
MIN_VISIBLE_FRACTION = 1e-4


def wrist_mount(world: mujoco.MjSpec) -> mujoco.MjsCamera:
    found = [c for c in world.cameras if c.name == WRIST_MJCF_NAME or c.name.endswith("/" + WRIST_MJCF_NAME)]
    if len(found) != 1:
        raise ValueError(f"camera system: the robot has no (unique) {WRIST_MJCF_NAME!r} camera; "
                         "DROID camera systems need franka_droid")
    return found[0]


def arm_root(find_body: Callable[[str], mujoco.MjsBody | None]) -> mujoco.MjsBody:
    body = find_body(ARM_ROOT)
    if body is None:
        raise ValueError(f"camera system: no body {ARM_ROOT!r} (DROID camera systems need franka_droid)")
    return body


def noisy_mount(pos: Vector, quat: Vector, fov: float, noise: MountNoise,
                rng: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """A mounted camera's pose (position, wxyz quaternion in its parent's frame) and fov with
    ``noise`` drawn from ``rng`` in MolmoSpaces' order: fov, position, orientation."""
    fov = fov + rng.uniform(*noise.fov)
    rot = Rotation.from_quat(np.asarray(quat, dtype=np.float64), scalar_first=True)
    moved = np.asarray(pos, dtype=np.float64) + rot.apply(rng.uniform(*noise.pos, size=3))
    limit = np.asarray(noise.rot_deg, dtype=np.float64)
    rot = rot * Rotation.from_euler("xyz", rng.uniform(-limit, limit, size=3), degrees=True)
    return moved, rot.as_quat(scalar_first=True), float(fov)


def gripper_body(env: Any) -> str:
    """The body holding the robot's TCP site (``franka_droid``: ``gripper/base``): the gripper the
    exocentric cameras must see."""
    return env.model.body(int(env.model.site_bodyid[env.robot.tcp_site])).name


def place_until_seen(env: Any, camera: str, must_see: Sequence[str], attempts: int,
                     draw: Callable[[], tuple[Vector, Vector, float]],
                     system: str) -> tuple[list[float], list[float], float]:
    """Set ``camera`` (a world camera of the probe scene ``env``) to ``draw()``'s pose until every
    body of ``must_see`` covers :data:`MIN_VISIBLE_FRACTION` of its image, at most ``attempts``
    times; the pose that passed, or a ``ValueError`` naming ``system`` when none did."""
    cid = env.model.camera(camera).id
    for _ in range(attempts):
        pos, quat, fovy = draw()
        env.model.cam_pos[cid], env.model.cam_quat[cid], env.model.cam_fovy[cid] = pos, quat, fovy
        if min(env.visible_fractions(camera, must_see).values()) >= MIN_VISIBLE_FRACTION:
            return [float(v) for v in pos], [float(v) for v in quat], float(fovy)
    raise ValueError(f"{system}: no placement of {camera} in {attempts} draws sees all of {list(must_see)} "
                     f"(each must cover {MIN_VISIBLE_FRACTION:g} of the image)")


def add_wrist(world: mujoco.MjSpec, pos: Vector, quat: Vector, fov: float) -> None:
    mount = wrist_mount(world)
    mount.parent.add_camera(name="wrist_camera", pos=list(pos), quat=list(quat), fovy=float(fov))


def task_objects(episode: Any) -> list[str]:
    """The bodies the exocentric cameras must see: ``task_relevant_objects``, else the task's
    target, receptacle and other receptacles."""
    if episode.task_relevant_objects:
        return list(dict.fromkeys(episode.task_relevant_objects))
    task = episode.task
    names = [getattr(task, "pickup_obj_name", None), getattr(task, "place_receptacle_name", None),
             *(getattr(task, "other_receptacle_names", None) or [])]
    return list(dict.fromkeys(n for n in names if n))
