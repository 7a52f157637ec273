"""Pose conversions: MolmoSpaces' 7-vector ``[x, y, z, qw, qx, qy, qz]``, MuJoCo's position +
rotation matrix, and 4x4 homogeneous transforms.

Quaternions are scalar first (wxyz), as MuJoCo and MolmoSpaces write them. The conversions are
MuJoCo's (``mju_mat2Quat``, ``mju_quat2Mat``), so a pose read from the simulation converts to
the same bits everywhere. Depends on nothing else of the package.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

#: a vector given as a list or an array
Vector = Sequence[float] | np.ndarray


def yaw_quat(yaw: float) -> list[float]:
    """The wxyz quaternion of a rotation by ``yaw`` about the world z axis."""
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


def quat_mul(a: Sequence[float], b: Sequence[float]) -> list[float]:
    """The Hamilton product ``a * b`` of two wxyz quaternions (``b`` applied first)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return [w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2]


def mat_to_quat(mat: np.ndarray) -> list[float]:
    """A rotation matrix (3x3 or MuJoCo's flat 9) as a wxyz quaternion."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(mat, dtype=np.float64).reshape(9))
    return quat.tolist()


def pose7(pos: Sequence[float] | np.ndarray, mat: np.ndarray) -> np.ndarray:
    """Position + rotation matrix as ``[x, y, z, qw, qx, qy, qz]``."""
    return np.concatenate([pos, mat_to_quat(mat)])


def unit_pose(pose: Sequence[float] | np.ndarray) -> np.ndarray:
    """``[x, y, z, qw, qx, qy, qz]`` with its quaternion scaled to unit length (files round them)."""
    pose = np.asarray(pose, dtype=np.float64)
    return np.concatenate([pose[:3], pose[3:] / np.linalg.norm(pose[3:])])


def pose_matrix(pose: Sequence[float] | np.ndarray) -> np.ndarray:
    """``[x, y, z, qw, qx, qy, qz]`` (unit quaternion; see :func:`unit_pose`) as a 4x4 transform."""
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(pose[3:7], dtype=np.float64))
    return frame_matrix(pose[:3], mat)


def frame_matrix(pos: Sequence[float] | np.ndarray, mat: np.ndarray) -> np.ndarray:
    """Position + rotation matrix (3x3 or MuJoCo's flat 9, e.g. ``data.xmat[body]``) as a 4x4 transform."""
    T = np.eye(4)
    T[:3, :3] = np.reshape(mat, (3, 3))
    T[:3, 3] = pos
    return T


def look_rotation(forward: Vector, up: Vector) -> np.ndarray:
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
