"""DROID camera systems for ``franka_droid`` (a camera plugin), as MolmoSpaces configures them
(``molmo_spaces/configs/camera_configs.py``), and MolmoSpaces' eval cameras
(:mod:`molmo_lerobot.cameras.franka_eval`), both built on :mod:`molmo_lerobot.cameras.franka_mounts`.

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

from molmo_lerobot import hookimpl
from molmo_lerobot.cameras.base import CameraSystem, episode_rng
from molmo_lerobot.cameras.franka_eval import FrankaEvalCameraSystem
from molmo_lerobot.cameras.franka_mounts import (
    EXO_CAMERA_1,
    MountNoise,
    add_wrist,
    arm_root,
    gripper_body,
    noisy_mount,
    place_until_seen,
    task_objects,
    wrist_mount,
)
from molmo_lerobot.hashing import episode_digest
from molmo_lerobot.poses import Vector, look_rotation, mat_to_quat

FIXED_WRIST_FOV = 56.74
RANDOM_WRIST_FOV = 52.0
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

    def place(self, env: Any) -> dict[str, tuple[Vector, Vector, float]]:
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
        pos = centre + np.array([distance * math.cos(azimuth), distance * math.sin(azimuth), height])
        lookat = centre + rng.uniform(*cam.lookat_noise, size=3)
        return pos, mat_to_quat(look_rotation(lookat - pos, (0.0, 0.0, 1.0))), fovy

    return draw


@hookimpl
def molmo_camera_systems() -> list[CameraSystem]:
    return [FrankaDroidCameraSystem(), FrankaRandomizedDroidCameraSystem(), FrankaEvalCameraSystem()]
