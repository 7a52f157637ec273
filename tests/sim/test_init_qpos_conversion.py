"""MolmoSpaces Franka files give the gripper as two finger-joint positions; both forms load."""

import numpy as np
import pytest

from molmo_lerobot.plugins import get_plugins


def test_franka_gripper_accepts_one_or_two_values():
    robot = get_plugins().robot("franka_droid")
    assert robot.init_qpos("gripper", [0.0]).tolist() == [0.0]
    assert robot.init_qpos("gripper", [0.04, 0.04]).tolist() == pytest.approx([0.0])  # fully open
    assert robot.init_qpos("gripper", [0.0, 0.0]).tolist() == pytest.approx([1.0])  # closed
    assert np.allclose(robot.init_qpos("arm", [0.1] * 7), 0.1)
    with pytest.raises(ValueError, match="expected 7 values, got 6"):
        robot.init_qpos("arm", [0.0] * 6)
    with pytest.raises(ValueError, match="expected 1 values, got 3"):
        robot.init_qpos("gripper", [0.0] * 3)
