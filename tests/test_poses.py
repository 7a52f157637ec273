"""Pose conversions (``molmo_lerobot.poses``) agree with each other and with scipy's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from molmo_lerobot.poses import frame_matrix, look_rotation, mat_to_quat, pose7, pose_matrix, unit_pose


def test_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        rot = Rotation.random(random_state=rng)
        pos = rng.normal(size=3)
        pose = pose7(pos, rot.as_matrix().reshape(9))
        assert np.allclose(Rotation.from_quat(pose[3:], scalar_first=True).as_matrix(), rot.as_matrix())
        T = pose_matrix(pose)
        assert np.allclose(T, frame_matrix(pos, rot.as_matrix())) and np.array_equal(T[:3, 3], pos)
        assert np.allclose(mat_to_quat(T[:3, :3]), pose[3:])


def test_unit_pose_scales_the_quaternion_only():
    pose = unit_pose([1.0, 2.0, 3.0, 0.70711, 0.0, 0.0, 0.70711])  # as a benchmark file rounds it
    assert np.isclose(np.linalg.norm(pose[3:]), 1.0) and list(pose[:3]) == [1.0, 2.0, 3.0]


def test_look_rotation():
    rot = look_rotation((1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    assert np.allclose(rot[:, 2], [-1.0, 0.0, 0.0]) and np.allclose(rot[:, 1], [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="parallel"):
        look_rotation((0.0, 0.0, 1.0), (0.0, 0.0, 2.0))
