"""rby1 / rby1m: MolmoSpaces' RB-Y1 loaded from their assets layout (a stand-in model made here,
tests/sim/rby1_standin.py: their model is gated), driven through its move groups, recorded with its
base group; a missing model is a one-line error naming where it was looked for."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from rby1_standin import write_standin

from molmo_lerobot.config import compose
from molmo_lerobot.context import RunContext
from molmo_lerobot.features import FeatureMap
from molmo_lerobot.paths import data_path
from molmo_lerobot.robots.rby1 import GROUPS, RBY1
from molmo_lerobot.runner.evaluate import run_evaluation

YAW = -0.5
START = [-0.9, 0.2, 0.0, math.cos(YAW / 2), 0.0, 0.0, math.sin(YAW / 2)]
GROUP_ORDER = ["base", "torso", "left_arm", "right_arm", "left_gripper", "right_gripper"]


def _episode(robot: str = "rby1", **init) -> dict:
    """A pick_v1 tabletop episode with the RB-Y1 on the floor behind the table, its own cameras."""
    raw = json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[0]
    raw["robot"] = {"robot_name": robot, "init_qpos": {"base": [0.0, 0.0, 0.0], "head": [0.0, 0.6], **init}}
    raw["cameras"] = []
    raw["img_resolution"] = [64, 48]
    raw["task"]["robot_base_pose"] = START
    return raw


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    root = tmp_path_factory.mktemp("mlspaces_assets")
    write_standin(root, "rby1")
    write_standin(root, "rby1m")
    return root


@pytest.fixture(scope="module")
def run(assets) -> RunContext:
    return RunContext.build({"molmospaces": {"assets_dir": str(assets)}})


def test_rby1_loads_their_model_and_its_groups_move_where_commanded(episode_env):
    env = episode_env(_episode())
    try:
        assert list(env.move_groups) == GROUP_ORDER
        assert env.joint_names["left_arm"] == [f"left_arm_{i}" for i in range(7)]
        obs = env.observe(images=False)
        assert obs["qpos"]["base"] == pytest.approx([START[0], START[1], YAW], abs=1e-9)  # robot_base_pose wins
        assert obs["qpos"]["left_arm"] == pytest.approx([0.5, 0.0, 0.0, -2.3, 0.0, -0.5, 0.0])
        assert obs["qpos"]["left_gripper"] == pytest.approx([0.0]) and obs["joint_qpos"]["left_gripper"] == \
            pytest.approx([-0.05, 0.05])  # their open fingers, coupled
        head = [env.model.jnt_qposadr[env.model.joint(f"robot_0/head_{i}").id] for i in range(2)]
        goal = {"base": np.array([-0.6, -0.1, YAW + 0.8]), "torso": np.array([0.0, 0.2, -0.4, 0.2, 0.0, 0.0]),
                "left_arm": np.array([0.3, 0.2, 0.1, -2.0, 0.1, -0.3, 0.2]),
                "right_arm": np.array([0.6, -0.2, 0.0, -2.1, 0.0, -0.6, -0.1]),
                "left_gripper": np.array([1.0]), "right_gripper": np.array([0.0])}
        for _ in range(40):  # 2.6 s: the arms swing as the base turns, then settle
            env.step(goal)
        obs = env.observe(images=False)
        for group in ("base", "torso", "left_arm", "right_arm"):
            assert obs["qpos"][group] == pytest.approx(goal[group], abs=0.02), group
        assert obs["qpos"]["left_gripper"][0] > 0.8 and obs["qpos"]["right_gripper"][0] < 0.05
        assert obs["robot_base_pose"][:2] == pytest.approx(goal["base"][:2], abs=0.02)  # follows the base
        assert env.data.qpos[head] == pytest.approx([0.0, 0.6], abs=0.02)  # the head is held, not commanded
        assert env.model.body_gravcomp[env.model.body("robot_0/link_left_arm_3").id] == 1.0
    finally:
        env.close()


def test_features_list_every_group_and_the_head_camera_renders(episode_env):
    env = episode_env(_episode())
    try:
        obs = env.observe(images=True)
        assert env.camera_system == "RBY1MjcfCameraSystem"
        assert env.camera_names == ["head_camera", "wrist_camera_l", "wrist_camera_r", "camera_follower"]
        assert env.model.cam_fovy[env.model.camera("head_camera").id] == pytest.approx(139.0)
        assert obs["images"]["head_camera"].shape == (48, 64, 3) and obs["images"]["head_camera"].std() > 0
        fmap = FeatureMap.from_observation(env.move_groups, env.joint_names, env.camera_names, obs)
        names = fmap.features()["action"]["names"]
        assert names[:9] == ["base_x", "base_y", "base_theta"] + [f"torso_{i}" for i in range(6)]
        assert names[-2:] == ["left_gripper", "right_gripper"] and len(names) == 25
    finally:
        env.close()


def test_rby1m_reads_its_own_file(run, assets):
    robot = run.plugins.robot("rby1m").configured(run.settings)
    world = robot.spec()
    assert world.body("robot_0/link_torso_5") is not None
    (assets / "robots" / "rby1m" / "rby1_v1.2_site_control.xml").rename(assets / "moved.xml")
    try:
        with pytest.raises(FileNotFoundError, match=r"robots/rby1m/rby1_v1\.2_site_control\.xml"):
            robot.spec()
    finally:
        (assets / "moved.xml").rename(assets / "robots" / "rby1m" / "rby1_v1.2_site_control.xml")


def test_a_missing_model_is_one_line_naming_the_path_and_the_install(tmp_path, monkeypatch, episode_env):
    monkeypatch.setenv("MLSPACES_ASSETS_DIR", str(tmp_path / "none"))
    run = RunContext.build()  # the episode of the tests above: their compiled model is cached for another dir
    with pytest.raises(FileNotFoundError) as err:
        episode_env(_episode(), run=run)
    msg = str(err.value)
    assert "\n" not in msg and str(tmp_path / "none" / "robots" / "rby1" / "rby1_site_control.xml") in msg
    assert "molmo-resources install robots/rby1@20251224" in msg


def test_a_model_without_their_names_is_refused_naming_the_file_and_the_names(tmp_path):
    path = write_standin(tmp_path)
    path.write_text(path.read_text().replace('"robot_0/torso_3"', '"robot_0/waist_3"'))
    match = r"rby1_site_control\.xml: not MolmoSpaces' RB-Y1 model .* no \['robot_0/torso_3'\]"
    with pytest.raises(ValueError, match=match):
        RBY1("rby1", "rby1_site_control.xml", str(tmp_path)).spec()


@pytest.mark.parametrize(("init", "match"), [
    ({"left_gripper": [0.02]}, r"robot\.init_qpos\['left_gripper'\]: finger positions \[0\.02\] outside"),
    ({"base": [1.0, 2.0]}, r"robot\.init_qpos\['base'\]: expected \[\] or \[x, y, yaw\], got 2"),
    ({"head": [0.1]}, r"robot\.init_qpos\['head'\]: expected 2 values, got 1"),
    ({"neck": [0.1]}, r"unknown move group\(s\) \['neck'\]")])
def test_bad_init_qpos_names_the_field(init, match, episode_env):
    with pytest.raises(ValueError, match=match):
        episode_env(_episode(**init))


def test_gripper_init_qpos_takes_their_metres():
    robot = RBY1("rby1", "rby1_site_control.xml")
    assert robot.init_qpos("left_gripper", [-0.05]) == pytest.approx([0.0])
    assert robot.init_qpos("left_gripper", [-0.025]) == pytest.approx([0.5])
    assert robot.init_qpos("right_gripper", [-0.01, 0.01]) == pytest.approx([0.8])
    assert robot.init_qpos("right_gripper", [0.0]) == pytest.approx([1.0])
    assert list(GROUPS) == [*GROUP_ORDER, "head"]


def test_an_rby1_run_records_a_dataset_with_its_base_group(tmp_path, assets, fork_servers):
    """End to end: molmo-eval on the stand-in (molmospaces.assets_dir), random policy, recorded."""
    bench = tmp_path / "bench"
    bench.mkdir()
    (bench / "benchmark.json").write_text(json.dumps([_episode()]))
    cfg = compose(["policy=random", f"benchmark.path={bench}", "workers=1", "record=true", "horizon=3",
                   f"output_dir={tmp_path / 'run'}", "progress=false", f"molmospaces.assets_dir={assets}"])
    res = run_evaluation(cfg, fork_servers)
    assert res.summary["n_errors"] == 0 and res.summary["n_episodes"] == 1
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("local/rby1", root=tmp_path / "run" / "dataset")
    assert ds.features["action"]["names"][:3] == ["base_x", "base_y", "base_theta"]
    assert "observation.images.head_camera" in ds.features and len(ds) == 3
