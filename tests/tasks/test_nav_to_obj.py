"""nav_to_obj (MolmoSpaces' NavToObjTask rule) at its boundaries, on constructed states of a nav_v1 house:
distance below ``succ_pos_threshold`` AND the nearest candidate visible from ``head_camera``."""

from __future__ import annotations

import copy
import json
import math
import os

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.paths import data_path
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.scripted_nav import ScriptedNav
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing
from molmo_lerobot.tasks.nav_to_obj import NavToObjTask, candidate_names, nav_prompt

EPISODE = 1  # "Navigate to any orange juice carton (2 available)"


def nav_v1() -> list[dict]:
    return json.loads((data_path("benchmarks") / "nav_v1" / "benchmark.json").read_text())


@pytest.fixture(scope="module")
def scene(run):
    """The episode's env at the end pose of the expert's plan (facing a candidate, ~1.2 m away)."""
    raw = nav_v1()[EPISODE]
    spec = parse_episode(raw, run.plugins)
    env = build_env(spec, Timing(), run, {})
    env.reset(0)
    expert = ScriptedNav({})
    expert.reset(EpisodeContext(spec=spec, episode_index=EPISODE, seed=0, prompt=spec.prompt,
                                move_groups=env.move_groups, policy_dt_s=0.066, env=env, catalog=run.catalog))
    yield env, raw, expert.plan[-1]
    env.close()


def _at(env, pose) -> None:
    env.robot.set_qpos(env.data, "base", np.asarray(pose, dtype=np.float64))
    mujoco.mj_forward(env.model, env.data)


def _task(run, env, raw: dict, **task) -> NavToObjTask:
    raw = copy.deepcopy(raw)
    raw["task"].update(task)
    t = NavToObjTask(parse_episode(raw, run.plugins).task, env)
    t.setup()
    return t


def test_the_candidates_prompt_and_threshold_are_theirs(run, scene):
    _, raw, _ = scene
    assert len(raw["task"]["pickup_obj_candidates"]) == 2
    assert raw["language"]["task_description"] == nav_prompt("orange juice carton", 2) == \
        "Navigate to any orange juice carton (2 available)"
    assert nav_prompt("mug") == "Navigate to the mug"
    assert parse_episode(raw, run.plugins).task.succ_pos_threshold == 1.5
    objects = {"a": {"category": "mug"}, "b": {"category": "bowl"}, "c": {"category": "mug"}}
    task = {**raw["task"], "pickup_obj_name": "a", "pickup_obj_candidates": ["a", "b", "c"],
            "pickup_obj_category": None}
    spec = parse_episode({**raw, "task": task}, run.plugins)
    assert candidate_names(spec.task, objects) == ["a", "c"]  # narrowed to the target's category, as theirs


def test_distance_boundary_and_reward(run, scene):
    env, raw, end = scene
    _at(env, end)
    task = _task(run, env, raw)
    name, d = task.nearest()
    assert 0.5 < d < 1.5 and task.visible(name)
    assert task.success() and task.reward() == pytest.approx(1.0 - d / 1.5)
    assert _task(run, env, raw, succ_pos_threshold=d + 1e-6).success()
    assert not _task(run, env, raw, succ_pos_threshold=d).success()  # reward 1 - d/d = 0 is no success
    assert not _task(run, env, raw, succ_pos_threshold=d - 1e-6).success()


def test_within_reach_but_unseen_is_no_success(run, scene):
    env, raw, end = scene
    _at(env, [end[0], end[1], end[2] + math.pi])  # the same spot, looking away
    task = _task(run, env, raw)
    assert task.nearest()[1] < 1.5 and not task.visible(task.nearest()[0])
    assert not task.success() and task.reward() == 0.0
    _at(env, end)
    assert task.success()  # the same task object re-judges the new state


def test_any_candidate_counts_and_only_the_nearest_is_judged(run, scene):
    env, raw, end = scene
    _at(env, end)
    near, _ = _task(run, env, raw).nearest()
    far = next(c for c in raw["task"]["pickup_obj_candidates"] if c != near)
    assert _task(run, env, raw, pickup_obj_name=far).success()  # any instance of the type
    alone = _task(run, env, raw, pickup_obj_name=far, pickup_obj_candidates=[far])
    assert alone.nearest()[0] == far and not alone.success()
    # a candidate moved away (no physics step): the state changed, so it is judged again
    adr = env.model.jnt_qposadr[env.model.body(near).jntadr[0]]
    saved = env.data.qpos[adr:adr + 3].copy()
    task = _task(run, env, raw)
    assert task.success()
    env.data.qpos[adr:adr + 3] = [saved[0], saved[1], 5.0]
    mujoco.mj_forward(env.model, env.data)
    assert not task.success()
    env.data.qpos[adr:adr + 3] = saved
    mujoco.mj_forward(env.model, env.data)


def test_errors_name_the_field(run, scene):
    env, raw, _ = scene
    with pytest.raises(ValueError, match=r"task\.pickup_obj_candidates: none of \['nope'\]"):
        _task(run, env, raw, pickup_obj_candidates=["nope"])
    with pytest.raises(ValueError, match=r"task\.pickup_obj_name: none of \['nope'\]"):
        _task(run, env, raw, pickup_obj_name="nope", pickup_obj_candidates=None)
    env.camera_names, names = ["wrist_camera"], env.camera_names
    try:
        with pytest.raises(ValueError, match=r"cameras: nav_to_obj judges visibility from 'head_camera'"):
            _task(run, env, raw)
    finally:
        env.camera_names = names
