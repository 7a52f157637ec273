"""The pick success rule on constructed simulator states."""

from __future__ import annotations

import copy
import os

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.tabletop.generate import generate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.robots.franka import FINGER_TRAVEL
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing


@pytest.fixture(scope="module")
def raw_episode():
    return generate_benchmark("pick", 1, 1, 3, "test")[0][0]


@pytest.fixture
def setup(raw_episode):
    run = RunContext.build()
    plugins = run.plugins
    spec = parse_episode(raw_episode, plugins)
    env = build_env(spec, Timing(), run)
    env.reset(0)
    task = plugins.task_type(spec.task.task_cls).create(spec, env)
    task.setup()
    yield env, task
    env.close()


def _hold_in_fingers(env, name):
    """Teleport object ``name`` between the fingers, its frame on the TCP, fingers just touching it."""
    site = env.robot.tcp_site
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, env.data.site_xmat[site])
    env._place(name, np.concatenate([env.data.site_xpos[site], quat]))
    width = 2 * BUILTIN_OBJECTS[name].half_extents[1]
    env.robot.set_qpos(env.data, "gripper", [1.0 - (width / 2 - 0.002) / FINGER_TRAVEL])
    mujoco.mj_forward(env.model, env.data)


def _lift_by(env, task, metres):
    """Make the object's current height ``metres`` above the recorded start height."""
    task.start_height = float(env.data.xpos[env.body_id(task.object_name)][2]) - metres


def test_start_state_is_not_success(setup):
    _env, task = setup
    assert task.lift() == pytest.approx(0.0, abs=1e-9) and not task.success() and task.reward() == 0.0


def test_threshold_with_only_robot_contact(setup):
    env, task = setup
    _hold_in_fingers(env, task.object_name)
    touching = env.contact_bodies(task.object_bodies)
    assert touching and touching <= env.robot.body_ids
    _lift_by(env, task, 0.0101)
    assert task.success() and task.reward() == 1.0
    _lift_by(env, task, 0.0099)
    assert not task.success()


def test_touching_nothing_is_not_success(setup):
    env, task = setup
    pose = env.body_pose(task.object_name)
    env._place(task.object_name, pose + np.array([0, 0, 0.2, 0, 0, 0, 0]))
    mujoco.mj_forward(env.model, env.data)
    assert task.lift() > 0.19 and not task.success()  # thrown in the air, not held


def test_touching_the_table_fails(setup):
    env, task = setup
    hold = {"arm": env.robot.targets(env.data, "arm"), "gripper": np.zeros(1)}
    env.step(hold)  # let the object settle into contact with the table
    _lift_by(env, task, 0.05)  # resting on the table, "lifted" by bookkeeping only
    assert env.model.body("table").id in env.contact_bodies(task.object_bodies)
    assert not task.success()


def test_touching_another_object_fails(setup):
    env, task = setup
    _hold_in_fingers(env, task.object_name)
    other = next(n for n in env.spec.scene_modifications.object_poses if n != task.object_name)
    pos = env.data.xpos[env.body_id(task.object_name)]
    # put the other object right under the held one, overlapping slightly
    drop = BUILTIN_OBJECTS[task.object_name].half_extents[2] + BUILTIN_OBJECTS[other].half_extents[2] - 0.002
    env._place(other, np.array([*pos[:2], pos[2] - drop, 1, 0, 0, 0]))
    mujoco.mj_forward(env.model, env.data)
    _lift_by(env, task, 0.05)
    assert env.body_id(other) in env.contact_bodies(task.object_bodies)
    assert not task.success()


def test_thresholds_and_horizon(raw_episode):
    run = RunContext.build()
    plugins = run.plugins
    tt = plugins.task_type("pick")
    assert plugins.task_type("molmo_spaces.tasks.pick_task.PickTask") is tt
    assert plugins.task_type("molmo_lerobot.tasks.pick.PickTask") is tt
    assert tt.default_horizon_sec == 20.0
    raw = copy.deepcopy(raw_episode)
    assert tt.thresholds(parse_episode(raw, plugins)) == {"succ_pos_threshold": 0.01}
    raw["task"]["succ_pos_threshold"] = 0.05
    assert tt.thresholds(parse_episode(raw, plugins)) == {"succ_pos_threshold": 0.05}


def test_unknown_pick_object_is_named(raw_episode):
    run = RunContext.build()
    plugins = run.plugins
    raw = copy.deepcopy(raw_episode)
    raw["task"]["pickup_obj_name"] = "unicorn"
    spec = parse_episode(raw, plugins)
    env = build_env(spec, Timing(), run)
    try:
        env.reset(0)
        with pytest.raises(ValueError, match=r"task.pickup_obj_name: no body 'unicorn'"):
            plugins.task_type("pick").create(spec, env)
    finally:
        env.close()
