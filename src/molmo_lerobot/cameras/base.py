"""Camera systems: how an episode's camera specs become MuJoCo cameras.

A :class:`CameraSystem` is what a camera plugin returns from ``molmo_camera_systems()``.
It edits the world spec before compilation; the environment then renders each named
camera at the episode's ``img_resolution``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import Any

import mujoco
import numpy as np


class CameraSystem(ABC):
    """Builds cameras into a world spec."""

    name: str
    aliases: tuple[str, ...] = ()

    @abstractmethod
    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None]) -> list[str]:
        """Add one MuJoCo camera per spec and return their names in order.

        ``find_body`` resolves a body name from a camera spec (robot bodies may carry a
        prefix in the assembled scene) and returns ``None`` when no such body exists.
        """


def look_rotation(forward: Sequence[float], up: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a MuJoCo camera (looks along -z, +y up) looking along ``forward``."""
    f = np.asarray(forward, dtype=np.float64)
    u = np.asarray(up, dtype=np.float64)
    if np.linalg.norm(f) < 1e-9:
        raise ValueError("camera forward direction is zero")
    f = f / np.linalg.norm(f)
    x = np.cross(f, u)
    if np.linalg.norm(x) < 1e-6:
        raise ValueError(f"camera up {list(u)} is parallel to its forward direction {list(f)}")
    x /= np.linalg.norm(x)
    y = np.cross(-f, x)
    return np.column_stack([x, y, -f])


def mat_to_quat(mat: np.ndarray) -> list[float]:
    """A rotation matrix as a wxyz quaternion."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(mat, dtype=np.float64).reshape(9))
    return quat.tolist()
