"""Environment: deterministic scenes and resets, cameras from specs, action validation."""

from __future__ import annotations

import numpy as np
import pytest

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing


def _rollout_state(spec, run, steps=5):
    env = build_env(spec, Timing(), run)
    try:
        env.reset(spec.seed)
        q = env.robot.targets(env.data, "arm")
        for k in range(steps):
            env.step({"arm": q + 0.02 * k, "gripper": np.array([k / steps])})
        return env.data.qpos.copy(), env.observe(images=False)
    finally:
        env.close()


def test_scene_and_reset_are_deterministic(pick_spec, run):
    qa, obs_a = _rollout_state(pick_spec, run)
    qb, obs_b = _rollout_state(pick_spec, run)
    assert np.array_equal(qa, qb)
    assert np.array_equal(obs_a["tcp_pose"], obs_b["tcp_pose"])


def test_reset_places_robot_and_objects(pick_spec, run):
    env = build_env(pick_spec, Timing(), run)
    try:
        env.reset(1)
        assert np.allclose(env.robot.qpos(env.data, "arm"), pick_spec.robot.init_qpos["arm"])
        for name, pose in pick_spec.scene_modifications.object_poses.items():
            assert np.allclose(env.body_pose(name), pose, atol=1e-6)
        assert env.move_groups == {"arm": 7, "gripper": 1}
        assert [len(v) for v in env.joint_names.values()] == [7, 1]
        assert not any("/" in n for names in env.joint_names.values() for n in names)
    finally:
        env.close()


def test_houses_differ_and_rebuild_identically(run):
    scene = run.plugins.scene_dataset("procedural_tabletop")
    a, b, c = (scene.build(h).compile() for h in (3, 3, 4))
    assert np.array_equal(a.geom_size, b.geom_size) and np.array_equal(a.geom_rgba, b.geom_rgba)
    assert a.geom_size.shape != c.geom_size.shape or not np.array_equal(a.geom_size, c.geom_size)
    with pytest.raises(ValueError, match="house_index -1 out of range"):
        scene.build(-1)


def test_cameras_follow_specs(pick_episodes, run):
    raw = dict(pick_episodes[0], img_resolution=[64, 48])
    spec = parse_episode(raw, run.plugins)
    env = build_env(spec, Timing(), run)
    try:
        env.reset(0)
        assert env.camera_names == ["exterior", "wrist"]
        exo = spec.camera("exterior")
        cam = env.model.camera("exterior")
        assert np.allclose(env.data.cam_xpos[cam.id], exo.pos)
        view = -env.data.cam_xmat[cam.id].reshape(3, 3)[:, 2]  # MuJoCo cameras look along -z
        assert np.allclose(view, np.asarray(exo.forward) / np.linalg.norm(exo.forward), atol=1e-6)
        wrist = env.model.camera("wrist")
        assert env.model.body(int(wrist.bodyid)).name.endswith("panda0_link7")
        assert np.allclose(env.model.cam_pos[wrist.id], spec.camera("wrist").camera_offset)
        assert env.model.cam_fovy[wrist.id] == pytest.approx(spec.camera("wrist").fov)
        obs = env.observe(images=True)
        assert obs["images"]["wrist"].shape == (48, 64, 3) and obs["images"]["wrist"].dtype == np.uint8
        assert obs["images"]["exterior"].std() > 5  # not a blank frame
    finally:
        env.close()


def test_robot_camera_with_unknown_body_is_rejected(pick_episodes, run):
    raw = dict(pick_episodes[0])
    raw["cameras"] = [dict(raw["cameras"][1], reference_body_names=["no_such_body"])]
    with pytest.raises(ValueError, match=r"cameras\[0\] \(wrist\): none of the reference bodies"):
        build_env(parse_episode(raw, run.plugins), Timing(), run)


@pytest.mark.parametrize(("action", "message"), [
    ({"arm": np.zeros(7)}, r"action has move groups \['arm'\], expected \['arm', 'gripper'\]"),
    ({"arm": np.zeros(6), "gripper": np.zeros(1)}, r"action\['arm'\] has shape \(6,\), expected \(7,\)"),
    ({"arm": np.zeros((2, 7)), "gripper": np.zeros(1)}, r"action\['arm'\] has shape \(2, 7\)"),
    ({"arm": np.zeros(7), "gripper": np.array([np.nan])}, r"action\['gripper'\] has non-finite"),
    ({"arm": np.zeros(7), "gripper": np.zeros(1), "base": np.zeros(3)}, "expected"),
])
def test_bad_actions_are_rejected(pick_spec, run, action, message):
    env = build_env(pick_spec, Timing(), run)
    try:
        env.reset(0)
        with pytest.raises(ValueError, match=message):
            env.step(action)
        assert env.data.time == 0.0  # nothing ran
    finally:
        env.close()


@pytest.mark.parametrize(("edit", "message"), [
    (lambda r: r["robot"]["init_qpos"].update(arm=[0.0] * 6), r"robot.init_qpos\['arm'\]: expected 7 values, got 6"),
    (lambda r: r["robot"]["init_qpos"].update(base=[0.0]), r"robot.init_qpos: unknown move group"),
    (lambda r: r["scene_modifications"]["object_poses"].update(ghost=[0, 0, 1, 1, 0, 0, 0]),
     r"object_poses\['ghost'\]: no body 'ghost'"),
])
def test_bad_episode_fields_are_named(pick_episodes, run, edit, message):
    import copy

    raw = copy.deepcopy(pick_episodes[0])
    edit(raw)
    env = build_env(parse_episode(raw, run.plugins), Timing(), run)
    try:
        with pytest.raises(ValueError, match=message):
            env.reset(0)
    finally:
        env.close()
