"""Open/close success rules on constructed simulator states, at the threshold boundaries."""

from __future__ import annotations

import os

import mujoco
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.articulated.generate import generate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing


@pytest.fixture(scope="module")
def plugins():
    return Plugins()


@pytest.fixture(scope="module")
def open_episodes():
    return generate_benchmark("open", 6, 1, 0, "test")[0]


@pytest.fixture(scope="module")
def close_episodes():
    return generate_benchmark("close", 2, 1, 0, "test")[0]


def _setup(plugins, raw: dict, **task_update):
    raw = {**raw, "task": {**raw["task"], **task_update}}
    spec = parse_episode(raw, plugins)
    env = build_env(spec, Timing(), RunContext.build())
    env.reset(0)
    task = plugins.task_type(spec.task_name).create(spec, env)
    task.setup()
    return spec, env, task


def _set_fraction(env, joint_name: str, fraction: float) -> None:
    m, d = env.model, env.data
    j = m.joint(joint_name).id
    lo, hi = m.jnt_range[j]
    d.qpos[m.jnt_qposadr[j]] = fraction * (hi if abs(hi) >= abs(lo) else lo)
    mujoco.mj_forward(m, d)


def test_open_and_close_resolve_from_molmospaces_opening_task(plugins, open_episodes, close_episodes):
    o = parse_episode(open_episodes[0], plugins)
    c = parse_episode(close_episodes[0], plugins)
    assert o.task.task_cls == c.task.task_cls == "molmo_spaces.tasks.opening_tasks.OpeningTask"
    assert plugins.task_type(o.task_name).name == "open" and plugins.task_type(c.task_name).name == "close"
    assert plugins.task_type("close").thresholds(c) == {"task_success_threshold": 0.2}
    assert plugins.expert("close").factory.__name__ == "ScriptedArticulated"


@pytest.mark.parametrize("fraction, expected", [(0.19, False), (0.21, True)])
def test_open_threshold_boundary(plugins, open_episodes, fraction, expected):
    spec, env, task = _setup(plugins, open_episodes[0])
    assert not task.success()  # open episodes start closed
    _set_fraction(env, spec.task.joint_name, fraction)
    assert task.success() is expected
    assert task.reward() == pytest.approx(fraction, abs=1e-9)


@pytest.mark.parametrize("fraction, expected", [(0.81, False), (0.79, True)])
def test_close_threshold_boundary(plugins, close_episodes, fraction, expected):
    spec, env, task = _setup(plugins, close_episodes[0])
    assert 0.95 <= task.fraction() <= 1.0 and not task.success()  # close episodes start open
    _set_fraction(env, spec.task.joint_name, fraction)
    assert task.success() is expected  # 1 - 0.81 = 0.19 < 0.2 <= 1 - 0.79


def test_open_counts_any_joint_of_the_object_close_only_its_own(plugins, open_episodes):
    raw = next(e for e in open_episodes if e["task"]["pickup_obj_name"] == "kitchen_hinge_cabinet")
    spec, env, task = _setup(plugins, raw)
    other = next(n for n in ("kitchen_hinge_cabinet/left_hinge_cabinet", "kitchen_hinge_cabinet/right_hinge_cabinet")
                 if n != spec.task.joint_name)
    _set_fraction(env, other, 0.21)
    assert task.success()  # MolmoSpaces: the max over the object's joints
    _, env_c, close = _setup(plugins, {**raw, "task": {**raw["task"], "task_type": "close"}})
    _set_fraction(env_c, spec.task.joint_name, 0.9)
    _set_fraction(env_c, other, 0.0)
    assert not close.success()  # close judges its own joint only


def test_custom_threshold_is_used_and_reported(plugins, open_episodes):
    spec, env, task = _setup(plugins, open_episodes[0], task_success_threshold=0.5)
    _set_fraction(env, spec.task.joint_name, 0.45)
    assert not task.success()
    assert plugins.task_type("open").thresholds(spec) == {"task_success_threshold": 0.5}


def test_start_state_list_gives_the_named_joint_its_first_value(plugins, open_episodes):
    """MolmoSpaces reads ``joint_start_position[0]`` and sets ``joint_name`` only."""
    raw = next(e for e in open_episodes if e["task"]["pickup_obj_name"] == "kitchen_hinge_cabinet")
    _spec, env, task = _setup(plugins, raw, joint_start_position=[-0.3, 9.0])  # the second value is ignored
    m, q = env.model, -0.3
    qs = {m.joint(j).name: float(env.data.qpos[m.jnt_qposadr[j]]) for j in task.joints}
    assert qs.pop(m.joint(task.joint).name) == pytest.approx(q)
    assert all(v == 0.0 for v in qs.values())


@pytest.mark.parametrize("update, message", [
    ({"joint_name": "kitchen_microwave/nope"}, "task.joint_name: no joint"),
    ({"joint_start_position": 5.0}, "task.joint_start_position: 5.0 outside the range"),
    ({"joint_start_position": []}, "task.joint_start_position: empty list"),
    ({"joint_index": 7}, "task.joint_index: 7 out of range"),
    ({"pickup_obj_name": "table"}, "has no hinge or slide joint"),
])
def test_bad_specs_name_the_field(plugins, open_episodes, update, message):
    with pytest.raises(ValueError, match=message):
        _setup(plugins, open_episodes[0], **update)
