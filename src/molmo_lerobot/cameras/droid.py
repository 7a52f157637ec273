"""DROID camera systems for ``franka_droid`` (a camera plugin), as MolmoSpaces configures them
(``molmo_spaces/configs/camera_configs.py``); MolmoSpaces' eval cameras, built on the same parts,
are in :mod:`molmo_lerobot.cameras.franka_eval`.

``FrankaDroidCameraSystem`` (alias ``droid``): fixed cameras, no noise —

* ``wrist_camera``: the robot's own ``gripper/wrist_camera`` (on ``gripper/base``), fov 56.74°;
* ``exo_camera_1``: DROID's shoulder camera, fixed to ``fr3_link0`` at ``[0.1, 0.57, 0.66]``, fov 71°.

``FrankaRandomizedDroidCameraSystem`` (alias ``droid_randomized``): the wrist camera with fov
noise ±4°, position noise (±15/±5/±10 mm in the camera frame) and orientation noise
(±8°/±4°/±4° about x/y/z); ``exo_camera_1`` and ``exo_camera_2`` (ZED 2 analogues: 0.2–0.8 m
from the workspace centre, 0.05–0.6 m above it, any azimuth, fov 64–72°) and ``exo_camera_3``
(a GoPro analogue: 0.2–0.5 m, 0.1–0.6 m above, fov 137–140°), each looking at the workspace
centre with the look-at point jittered ±0.1 m. The workspace centre is the centroid of the
task's objects (``task_relevant_objects``, else the target, the receptacle and the other
receptacles) and the gripper's TCP in the reset scene. An exocentric placement is drawn again
until every task object and the gripper cover at least 1e-4 of its pixels (a segmentation
render), at most 100 times (20 for ``exo_camera_3``); when no draw passes, the episode fails to
build, as in MolmoSpaces. Every draw comes from generators seeded by the episode's content, so
an episode always gets the same cameras, on any worker.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from molmo_lerobot import hookimpl
from molmo_lerobot.cameras.base import CameraSystem, episode_rng
from molmo_lerobot.hashing import episode_digest
from molmo_lerobot.poses import look_rotation, mat_to_quat

WRIST_MJCF_NAME = "gripper/wrist_camera"
ARM_ROOT = "fr3_link0"
#: DROID's shoulder camera: offset and wxyz quaternion in fr3_link0's frame, fov
EXO_CAMERA_1 = ((0.1, 0.57, 0.66), (-0.3633, -0.1241, 0.4263, 0.8191), 71.0)
FIXED_WRIST_FOV = 56.74
RANDOM_WRIST_FOV = 52.0


@dataclass(frozen=True)
class MountNoise:
    """Noise of a camera on its mount: fov (deg, added), position (m, per axis of the camera's
    frame) and orientation (deg, ± per x/y/z Euler angle, applied in the camera's frame)."""

    fov: tuple[float, float]
    pos: tuple[tuple[float, float, float], tuple[float, float, float]]
    rot_deg: tuple[float, float, float]


RANDOM_WRIST_NOISE = MountNoise((-4.0, 4.0), ((-0.015, -0.005, -0.01), (0.015, 0.005, 0.01)), (8.0, 4.0, 4.0))


@dataclass(frozen=True)
class ExoDraw:
    """A randomized exocentric camera around the workspace centre (ranges in metres, radians, degrees)."""

    name: str
    distance: tuple[float, float]
    height: tuple[float, float]
    fov: tuple[float, float]
    attempts: int
    azimuth: tuple[float, float] = (0.0, 2 * math.pi)
    lookat_noise: tuple[float, float] = (-0.1, 0.1)


RANDOM_EXO_CAMERAS = (
    ExoDraw("exo_camera_1", (0.2, 0.8), (0.05, 0.6), (64.0, 72.0), 100),
    ExoDraw("exo_camera_2", (0.2, 0.8), (0.05, 0.6), (64.0, 72.0), 100),
    ExoDraw("exo_camera_3", (0.2, 0.5), (0.1, 0.6), (137.0, 140.0), 20),
)
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


def noisy_mount(pos: Sequence[float], quat: Sequence[float], fov: float, noise: MountNoise,
                rng: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """A mounted camera's pose (position, wxyz quaternion in its parent's frame) and fov with
    ``noise`` drawn from ``rng`` in MolmoSpaces' order: fov, position, orientation."""
    fov = fov + rng.uniform(*noise.fov)
    rot = Rotation.from_quat(np.asarray(quat, dtype=np.float64), scalar_first=True)
    pos = np.asarray(pos, dtype=np.float64) + rot.apply(rng.uniform(*noise.pos, size=3))
    limit = np.asarray(noise.rot_deg, dtype=np.float64)
    rot = rot * Rotation.from_euler("xyz", rng.uniform(-limit, limit, size=3), degrees=True)
    return pos, rot.as_quat(scalar_first=True), float(fov)


def gripper_body(env: Any) -> str:
    """The body holding the robot's TCP site (``franka_droid``: ``gripper/base``): the gripper the
    exocentric cameras must see."""
    return env.model.body(int(env.model.site_bodyid[env.robot.tcp_site])).name


def place_until_seen(env: Any, camera: str, must_see: Sequence[str], attempts: int,
                     draw: Callable[[], tuple[Sequence[float], Sequence[float], float]],
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


def add_wrist(world: mujoco.MjSpec, pos: Sequence[float], quat: Sequence[float], fov: float) -> None:
    mount = wrist_mount(world)
    mount.parent.add_camera(name="wrist_camera", pos=list(pos), quat=list(quat), fovy=float(fov))


class FrankaDroidCameraSystem(CameraSystem):
    """Wrist camera + DROID's shoulder camera, fixed (module docstring)."""

    name = "FrankaDroidCameraSystem"
    aliases = ("droid",)

    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None], episode: Any = None) -> list[str]:
        mount = wrist_mount(world)
        add_wrist(world, mount.pos, mount.quat, FIXED_WRIST_FOV)
        offset, quat, fov = EXO_CAMERA_1
        arm_root(find_body).add_camera(name="exo_camera_1", pos=list(offset), quat=list(quat), fovy=fov)
        return ["wrist_camera", "exo_camera_1"]


def task_objects(episode: Any) -> list[str]:
    """The bodies the exocentric cameras must see: ``task_relevant_objects``, else the task's
    target, receptacle and other receptacles."""
    if episode.task_relevant_objects:
        return list(dict.fromkeys(episode.task_relevant_objects))
    task = episode.task
    names = [getattr(task, "pickup_obj_name", None), getattr(task, "place_receptacle_name", None),
             *(getattr(task, "other_receptacle_names", None) or [])]
    return list(dict.fromkeys(n for n in names if n))


class FrankaRandomizedDroidCameraSystem(CameraSystem):
    """Wrist camera with noise + three randomized exocentric cameras that see the task, seeded by
    the episode (module docstring)."""

    name = "FrankaRandomizedDroidCameraSystem"
    aliases = ("droid_randomized",)
    places_in_scene = True

    def episode_key(self, episode: Any) -> str:
        return episode_digest(episode).hex()

    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None], episode: Any = None) -> list[str]:
        if episode is None:
            raise ValueError(f"{self.name} needs the episode (its randomization is seeded by it)")
        mount = wrist_mount(world)
        pos, quat, fov = noisy_mount(mount.pos, mount.quat, RANDOM_WRIST_FOV, RANDOM_WRIST_NOISE, episode_rng(episode))
        add_wrist(world, pos, quat, fov)
        for cam in RANDOM_EXO_CAMERAS:  # placed by place() once the scene is compiled
            world.worldbody.add_camera(name=cam.name, pos=[0.0, 0.0, 0.0])
        return ["wrist_camera"] + [cam.name for cam in RANDOM_EXO_CAMERAS]

    def place(self, env: Any) -> dict[str, tuple[Sequence[float], Sequence[float], float]]:
        objects = task_objects(env.spec)
        centre = np.mean([*(env.data.xpos[env.body_id(name, "task_relevant_objects")] for name in objects),
                          env.data.site_xpos[env.robot.tcp_site]], axis=0)
        rng = episode_rng(env.spec, stream=1)
        return {cam.name: place_until_seen(env, cam.name, [*objects, gripper_body(env)], cam.attempts,
                                           random_exo_draws(cam, centre, rng), self.name)
                for cam in RANDOM_EXO_CAMERAS}


def random_exo_draws(cam: ExoDraw, centre: np.ndarray, rng: Any) -> Callable[[], tuple[np.ndarray, list[float], float]]:
    """Draws of ``cam`` around ``centre`` in MolmoSpaces' order (fov once; then per draw distance,
    azimuth, height and the look-at jitter), each looking at the jittered centre."""
    fovy = float(rng.uniform(*cam.fov))

    def draw() -> tuple[np.ndarray, list[float], float]:
        distance, azimuth, height = rng.uniform(*cam.distance), rng.uniform(*cam.azimuth), rng.uniform(*cam.height)
        pos = centre + [distance * math.cos(azimuth), distance * math.sin(azimuth), height]
        lookat = centre + rng.uniform(*cam.lookat_noise, size=3)
        return pos, mat_to_quat(look_rotation(lookat - pos, (0.0, 0.0, 1.0))), fovy

    return draw


@hookimpl
def molmo_camera_systems() -> list[CameraSystem]:
    from molmo_lerobot.cameras.franka_eval import FrankaEvalCameraSystem  # built on this module's parts

    return [FrankaDroidCameraSystem(), FrankaRandomizedDroidCameraSystem(), FrankaEvalCameraSystem()]
