"""The camera system of ``rby1`` / ``rby1m`` (a camera plugin): ``RBY1MjcfCameraSystem`` (alias
``rby1``), MolmoSpaces' camera system of the same name — the cameras their RB-Y1 model carries,
each rendered under its own name from where the model mounts it:

* ``head_camera`` (on the head), at their fov 139° (a GoPro's wide view);
* ``wrist_camera_l`` / ``wrist_camera_r`` (on the hands) and ``camera_follower``, at the model's fov.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import mujoco

from molmo_lerobot import hookimpl
from molmo_lerobot.cameras.base import CameraSystem

NAMESPACE = "robot_0/"
#: their cameras: name (in the model and in the recording) -> fov (deg) or None for the model's
CAMERAS: dict[str, float | None] = {"head_camera": 139.0, "wrist_camera_l": None, "wrist_camera_r": None,
                                    "camera_follower": None}


class RBY1MjcfCameraSystem(CameraSystem):
    """The RB-Y1 model's own cameras (module docstring)."""

    name = "RBY1MjcfCameraSystem"
    aliases = ("rby1",)

    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None], episode: Any = None) -> list[str]:
        for name, fov in CAMERAS.items():
            mount = world.camera(NAMESPACE + name)
            if mount is None:
                raise ValueError(f"camera system {self.name}: the robot has no camera {NAMESPACE + name!r} "
                                 "(it needs MolmoSpaces' RB-Y1 model: rby1 or rby1m)")
            mount.parent.add_camera(name=name, pos=list(mount.pos), quat=list(mount.quat),
                                    fovy=float(mount.fovy if fov is None else fov))
        return list(CAMERAS)


@hookimpl
def molmo_camera_systems() -> list[CameraSystem]:
    return [RBY1MjcfCameraSystem()]
