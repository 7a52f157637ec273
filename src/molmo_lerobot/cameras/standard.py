"""The standard camera system (a camera plugin): robot-mounted and exocentric cameras from specs.

Robot-mounted: the camera is fixed to the first of ``reference_body_names`` found in the
scene, at ``camera_offset`` in that body's frame. Its orientation in the body frame is
``camera_quaternion`` (wxyz, MuJoCo camera convention: looks along -z, +y up); when that
quaternion is the identity and ``lookat_offset`` differs from ``camera_offset``, the
camera instead looks from the offset at ``lookat_offset``, keeping the body's +x up when
possible. Exocentric: a world camera at ``pos`` looking along ``forward`` with ``up``.
``fov`` is the vertical field of view in degrees.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.cameras.base import STANDARD, CameraSystem
from molmo_lerobot.poses import look_rotation, mat_to_quat


def _lookat_quat(offset: Sequence[float], lookat: Sequence[float]) -> list[float]:
    forward = np.asarray(lookat, dtype=np.float64) - np.asarray(offset, dtype=np.float64)
    for up in ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)):
        if np.linalg.norm(np.cross(forward, up)) > 1e-3 * np.linalg.norm(forward):
            return mat_to_quat(look_rotation(forward, up))
    raise ValueError("camera lookat_offset equals camera_offset")


class StandardCameras(CameraSystem):
    """Cameras exactly as the episode's camera specs describe them."""

    name = STANDARD

    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None], episode: Any = None) -> list[str]:
        names: list[str] = []
        for i, cam in enumerate(cameras):
            if cam.name in names:
                raise ValueError(f"cameras[{i}]: duplicate camera name {cam.name!r}")
            if not 0 < cam.fov < 180:
                raise ValueError(f"cameras[{i}] ({cam.name}): fov must be in (0, 180) degrees, got {cam.fov}")
            if cam.type == "exocentric":
                quat = mat_to_quat(look_rotation(cam.forward, cam.up))
                world.worldbody.add_camera(name=cam.name, pos=list(cam.pos), quat=quat, fovy=float(cam.fov))
            else:
                body = next((b for b in map(find_body, cam.reference_body_names) if b is not None), None)
                if body is None:
                    raise ValueError(f"cameras[{i}] ({cam.name}): none of the reference bodies "
                                     f"{cam.reference_body_names} is in the scene")
                quat = [float(q) for q in cam.camera_quaternion]
                if np.allclose(quat, [1.0, 0.0, 0.0, 0.0]) and not np.allclose(cam.lookat_offset, cam.camera_offset):
                    quat = _lookat_quat(cam.camera_offset, cam.lookat_offset)
                body.add_camera(name=cam.name, pos=list(cam.camera_offset), quat=quat, fovy=float(cam.fov))
            names.append(cam.name)
        return names


@hookimpl
def molmo_camera_systems() -> list[CameraSystem]:
    return [StandardCameras()]
