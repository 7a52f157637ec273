"""The door_opening rule (MolmoSpaces' DoorOpeningTask) on constructed states in door_rooms houses.

The rule only reads the door and the robot base pose, so these tests seat ``franka_droid`` (a fixed
base, cheaper) where the episodes put ``mobile_franka``.
"""

from __future__ import annotations

import json
import os

import mujoco
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.load import BenchmarkError, load_benchmark
from molmo_lerobot.benchmark.task_specs import DoorOpeningTaskSpec, parse_episode
from molmo_lerobot.content.doors.generate import generate_benchmark
from molmo_lerobot.content.doors.scenes import DOOR_RANGE, HINGE_JOINT, door_geometry
from molmo_lerobot.context import RunContext
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing


@pytest.fixture(scope="module")
def plugins():
    return Plugins()


@pytest.fixture(scope="module")
def episodes():
    return generate_benchmark(2, 2, 0, "test")[0]


def _stand_in(raw: dict) -> dict:
    return {**raw, "robot": {"robot_name": "franka_droid", "init_qpos": {}}}


def _setup(plugins, raw: dict, **task_update):
    raw = _stand_in({**raw, "task": {**raw["task"], **task_update}})
    spec = parse_episode(raw, plugins)
    env = build_env(spec, Timing(), RunContext.build())
    env.reset(0)
    task = plugins.task_type(spec.task_name).create(spec, env)
    task.setup()
    return spec, env, task


def _set_hinge(env, q: float) -> None:
    m = env.model
    env.data.qpos[m.jnt_qposadr[m.joint(HINGE_JOINT).id]] = q
    mujoco.mj_forward(m, env.data)


def _molmospaces_episode(raw: dict) -> dict:
    """The shape their door sampler writes: their task_type name, no range / reset state / threshold."""
    task = {k: v for k, v in raw["task"].items()
            if k not in ("articulated_joint_range", "articulated_joint_reset_state", "door_openness_threshold",
                         "task_horizon_sec")}
    source = {"h5_file": "house_7/trajectories.h5", "traj_key": "traj_0"}
    return {**raw, "task": {**task, "task_type": "door_open"}, "source": source}


def test_molmospaces_door_episode_resolves_to_the_plugin(plugins, episodes):
    spec = parse_episode(_molmospaces_episode(episodes[0]), plugins)
    assert plugins.task_type(spec.task_name).name == "door_opening" and isinstance(spec.task, DoorOpeningTaskSpec)
    assert spec.task.door_openness_threshold == 0.67 and spec.task.articulated_joint_range is None
    assert plugins.task_type("door_opening").thresholds(spec) == {"door_openness_threshold": 0.67}
    assert plugins.expert("door_opening").factory.__name__ == "ScriptedDoor"


@pytest.mark.parametrize("fraction, expected", [(0.66, False), (0.68, True)])
def test_threshold_boundary(plugins, episodes, fraction, expected):
    _, env, task = _setup(plugins, episodes[0])
    assert task.openness() == 0.0 and not task.success()
    _set_hinge(env, fraction * episodes[0]["task"]["articulated_joint_range"][1])
    assert task.openness() == pytest.approx(fraction, abs=1e-6)
    assert task.success() is expected and task.reward() == float(expected)


def test_episode_range_and_reset_state_are_theirs(plugins, episodes):
    """Openness is (q - r0) / (r1 - r0) over the episode's range, clipped; the hinge starts at the reset state."""
    _, env, task = _setup(plugins, episodes[0], articulated_joint_range=[0.2, 1.2],
                          articulated_joint_reset_state=[0.4, 9.0], door_openness_threshold=0.5)
    hinge = env.model.joint(HINGE_JOINT).id
    assert env.data.qpos[env.model.jnt_qposadr[hinge]] == pytest.approx(0.4)
    assert task.openness() == pytest.approx(0.2) and not task.success()
    _set_hinge(env, 0.69)
    assert not task.success()
    _set_hinge(env, 0.71)
    assert task.success()
    _set_hinge(env, 0.1)
    assert task.openness() == 0.0


def test_without_a_range_the_hinge_range_counts(plugins, episodes):
    raw = _molmospaces_episode(episodes[0])
    _, env, task = _setup(plugins, raw)
    assert task.range == pytest.approx((0.0, DOOR_RANGE))
    _set_hinge(env, 0.68 * DOOR_RANGE)
    assert task.success()


def test_push_or_pull_follows_the_side_the_robot_starts_on(plugins, episodes):
    for raw in episodes:
        door = door_geometry(raw["house_index"])
        side = 1 if raw["task"]["robot_base_pose"][0] > 0 else -1
        _, _, task = _setup(plugins, raw)
        assert task.pushing is (side != door["swing_side"])
        assert task.description() == raw["language"]["task_description"]
        assert task.description() == ("Push the door open" if task.pushing else "Pull the door open")


@pytest.mark.parametrize("update, message", [
    ({"door_body_name": "nope"}, "task.door_body_name: no body 'nope'"),
    ({"door_body_name": "door/handle_pos"}, "task.door_body_name: 'door/handle_pos' has no hinge"),
    ({"articulated_joint_range": [0.5, 0.5]}, "task.articulated_joint_range: empty range"),
    ({"articulated_joint_reset_state": []}, r"articulated_joint_reset_state\n  Value error, expected at least 1 value"),
])
def test_bad_specs_name_the_field(plugins, episodes, update, message):
    with pytest.raises(ValueError, match=message):
        _setup(plugins, episodes[0], **update)


def test_validation_errors_name_file_episode_and_field(plugins, episodes, tmp_path):
    bad = [episodes[0], {**episodes[1], "task": {**episodes[1]["task"], "door_openness_threshold": 1.5}}]
    path = tmp_path / "doors.json"
    path.write_text(json.dumps(bad))
    with pytest.raises(BenchmarkError) as err:
        load_benchmark(path, plugins)
    message = str(err.value)
    assert "doors.json" in message and "episode 1" in message and "task.door_openness_threshold" in message


@pytest.mark.parametrize(("update", "expected"), [
    ({"articulated_joint_reset_state": [100.0]},
     ["task.articulated_joint_reset_state: 100 is outside the range", "is outside articulated_joint_range",
      "succeeds at step 0"]),
    ({"articulated_joint_range": [DOOR_RANGE, 0.0]},
     ["task.articulated_joint_range: [1.5708, 0] is reversed", "succeeds at step 0"]),
])
def test_a_start_molmospaces_accepts_but_is_odd_is_marked(plugins, episodes, update, expected):
    """MolmoSpaces sets the reset state and judges the episode's range unchecked (their DoorOpeningTask):
    such an episode runs, its task's start_warnings say why it is odd."""
    spec, env, task = _setup(plugins, episodes[0], **update)
    try:
        assert task.success()  # what a random policy was scored on
        assert len(task.start_warnings) == len(expected)
        for warning, text in zip(task.start_warnings, expected, strict=True):
            assert text in warning
        warned = plugins.task_type(spec.task_name).spec_problems(spec, lambda: None)
        assert warned and all(p.warning for p in warned)  # molmo-bench validate warns of them from the file
    finally:
        env.close()
    _, env, task = _setup(plugins, episodes[0])
    assert task.start_warnings == ()
    env.close()
