"""The camera system of ``mobile_franka`` (a camera plugin): ``MobileFrankaCameraSystem`` (alias ``mobile``).

* ``head_camera``: the robot's navigation camera ``robot_0/head_camera`` on its base, at the pose
  and fov the robot gives it (:mod:`molmo_lerobot.robots.mobile_franka`), under the name
  MolmoSpaces' nav task reads its visibility from;
* ``wrist_camera``: the robot's ``gripper/wrist_camera`` with the fixed DROID wrist fov, as
  ``FrankaDroidCameraSystem`` mounts it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import mujoco

from molmo_lerobot import hookimpl
from molmo_lerobot.cameras.base import CameraSystem
from molmo_lerobot.cameras.droid import FIXED_WRIST_FOV
from molmo_lerobot.cameras.franka_mounts import add_wrist, wrist_mount

HEAD_MJCF_NAME = "head_camera"


def head_mount(world: mujoco.MjSpec) -> mujoco.MjsCamera:
    """The robot's own head camera (``<namespace>head_camera``); ``ValueError`` if there is none."""
    found = [c for c in world.cameras if c.name.endswith("/" + HEAD_MJCF_NAME)]
    if len(found) != 1:
        raise ValueError(f"camera system: the robot has no (unique) {HEAD_MJCF_NAME!r} camera; "
                         "MobileFrankaCameraSystem needs mobile_franka")
    return found[0]


class MobileFrankaCameraSystem(CameraSystem):
    """Head (navigation) camera + wrist camera of ``mobile_franka`` (module docstring)."""

    name = "MobileFrankaCameraSystem"
    aliases = ("mobile",)

    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None], episode: Any = None) -> list[str]:
        head = head_mount(world)
        head.parent.add_camera(name=HEAD_MJCF_NAME, pos=list(head.pos), quat=list(head.quat), fovy=float(head.fovy))
        mount = wrist_mount(world)
        add_wrist(world, mount.pos, mount.quat, FIXED_WRIST_FOV)
        return [HEAD_MJCF_NAME, "wrist_camera"]


@hookimpl
def molmo_camera_systems() -> list[CameraSystem]:
    return [MobileFrankaCameraSystem()]
