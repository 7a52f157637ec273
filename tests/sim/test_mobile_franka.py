"""mobile_franka: the holonomic base drives where it is commanded, as one more move group."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.features import FeatureMap
from molmo_lerobot.paths import data_path

YAW = 0.4
START = [-1.2, 0.3, 0.005, math.cos(YAW / 2), 0.0, 0.0, math.sin(YAW / 2)]


def _episode(init_base: list[float] | None = None) -> dict:
    """A pick_v1 tabletop episode with mobile_franka standing on the floor beside the table."""
    raw = json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[0]
    raw["robot"] = {"robot_name": "mobile_franka",
                    "init_qpos": {"base": init_base or [], "arm": [0, -0.7853, 0, -2.35619, 0, 1.57079, 0.0],
                                  "gripper": [0.00296, 0.00296]}}
    raw["cameras"] = []
    raw["img_resolution"] = [96, 96]
    raw["task"]["robot_base_pose"] = START
    return raw


def test_base_starts_at_the_base_pose_and_drives_where_commanded(episode_env):
    env = episode_env(_episode())
    try:
        assert list(env.move_groups) == ["base", "arm", "gripper"]
        assert env.observe(images=False)["qpos"]["base"] == pytest.approx([START[0], START[1], YAW], abs=1e-9)
        arm = env.robot.targets(env.data, "arm")
        start, goal = np.array([START[0], START[1], YAW]), np.array([-0.6, -0.5, YAW - 1.0])
        for k in range(1, 21):  # a straight line in 20 policy steps, then 10 steps to settle
            env.step({"base": start + (goal - start) * k / 20, "arm": arm, "gripper": np.array([0.0])})
        for _ in range(10):
            env.step({"base": goal, "arm": arm, "gripper": np.array([0.0])})
        obs = env.observe(images=False)
        assert obs["qpos"]["base"] == pytest.approx(goal, abs=2e-3)
        body = env.model.body("robot_0/base").id
        assert env.data.xpos[body][:2] == pytest.approx(goal[:2], abs=2e-3)
        assert math.atan2(env.data.xmat[body][3], env.data.xmat[body][0]) == pytest.approx(goal[2], abs=2e-3)
        assert obs["qpos"]["arm"] == pytest.approx(arm, abs=0.02)  # the arm rides along, held
        assert obs["robot_base_pose"][:2] == pytest.approx(goal[:2], abs=2e-3)  # the base pose follows the robot
    finally:
        env.close()


def test_robot_base_pose_wins_over_init_qpos_base_and_features_list_the_base(episode_env):
    env = episode_env(_episode([0.0, 0.0, 0.0]))  # what their files write; their eval then sets robot_base_pose
    try:
        obs = env.observe(images=True)
        assert obs["qpos"]["base"] == pytest.approx([START[0], START[1], YAW], abs=1e-9)
        assert env.camera_system == "MobileFrankaCameraSystem" and env.camera_names == ["head_camera", "wrist_camera"]
        assert obs["images"]["head_camera"].shape == (96, 96, 3) and obs["images"]["head_camera"].std() > 0
        fmap = FeatureMap.from_observation(env.move_groups, env.joint_names, env.camera_names, obs)
        feats = fmap.features()
        assert feats["action"]["names"][:3] == ["base_x", "base_y", "base_theta"]
        assert feats["action"]["shape"] == (11,) and feats["observation.state"]["names"][:3] == ["base_x", "base_y",
                                                                                                  "base_theta"]
        assert "observation.images.head_camera" in feats
        assert fmap.split_action(fmap.action_vector({"base": [1, 2, 3], "arm": [0] * 7, "gripper": [0]}))["base"] \
            .tolist() == [1, 2, 3]
    finally:
        env.close()


def test_a_base_init_qpos_of_another_size_is_an_error_naming_the_field(episode_env):
    with pytest.raises(ValueError, match=r"robot\.init_qpos\['base'\]: expected \[\] or \[x, y, yaw\], got 2"):
        episode_env(_episode([1.0, 2.0]))
