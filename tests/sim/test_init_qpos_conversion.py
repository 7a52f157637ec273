"""init_qpos gripper semantics per robot: MolmoSpaces' franka_droid gives Robotiq driver radians
(``[0.00296, 0.00296]`` = open), the Panda takes finger metres; both accept one normalized value."""

import numpy as np
import pytest

from molmo_lerobot.plugins import Plugins


def test_franka_droid_reads_driver_radians_open():
    robot = Plugins().robot("franka_droid")
    assert robot.name == "franka_droid"
    open_ = robot.init_qpos("gripper", [0.00296, 0.00296])
    assert open_[0] < 0.01  # open (the old finger-metre reading made it 93 % closed)
    assert robot.init_qpos("gripper", [0.8, 0.8]).tolist() == pytest.approx([1.0])
    assert robot.init_qpos("gripper", [0.4, 0.4]).tolist() == pytest.approx([0.5])
    assert robot.init_qpos("gripper", [0.0]).tolist() == [0.0]
    with pytest.raises(ValueError, match="outside"):
        robot.init_qpos("gripper", [0.04, 3.0])
    with pytest.raises(ValueError, match="expected 7 values, got 6"):
        robot.init_qpos("arm", [0.0] * 6)


def test_panda_reads_finger_metres_and_is_not_franka_droid():
    robot = Plugins().robot("franka")
    assert "franka_droid" not in (robot.name, *robot.aliases)
    assert robot.init_qpos("gripper", [0.0]).tolist() == [0.0]
    assert robot.init_qpos("gripper", [0.04, 0.04]).tolist() == pytest.approx([0.0])  # fully open
    assert robot.init_qpos("gripper", [0.0, 0.0]).tolist() == pytest.approx([1.0])  # closed
    assert np.allclose(robot.init_qpos("arm", [0.1] * 7), 0.1)
    with pytest.raises(ValueError, match="expected 1 values, got 3"):
        robot.init_qpos("gripper", [0.0] * 3)
