"""Built-in sim policies through the real rollout loop: the scripted expert picks, random does not."""

from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.generate import generate_benchmark  # noqa: E402
from molmo_lerobot.benchmark.schema import EpisodeSpec  # noqa: E402
from molmo_lerobot.plugins import get_plugins  # noqa: E402
from molmo_lerobot.policies.base import EpisodeContext  # noqa: E402
from molmo_lerobot.runner.rollout import rollout  # noqa: E402
from molmo_lerobot.runner.episode_env import build_env  # noqa: E402
from molmo_lerobot.sim.env import Timing  # noqa: E402

HORIZON = 100  # the script needs about 60 policy steps; 100 also checks that the hold lasts


@pytest.fixture(scope="module")
def episodes():
    return generate_benchmark("pick", 2, 1, 11, "test")[0]


def _run(raw, policy_name, horizon=HORIZON, config=None):
    plugins = get_plugins()
    spec = EpisodeSpec.model_validate(raw)
    timing = Timing()
    policy = plugins.policy(policy_name).factory({"name": policy_name, **(config or {})})
    env = build_env(spec, timing, plugins)
    try:
        env.reset(spec.seed)
        task = plugins.task_type(spec.task.task_cls).create(spec, env)
        ctx = EpisodeContext(spec=spec, episode_index=0, seed=spec.seed, prompt=spec.prompt,
                             move_groups=env.move_groups, policy_dt_s=timing.policy_dt_s, env=env)
        outcome = rollout(env, task, policy, ctx, horizon, [], None, policy_name)
        return outcome, env.data.qpos.copy()
    finally:
        env.close()


def test_scripted_picks_two_episodes(episodes):
    for raw in episodes:
        outcome, _ = _run(raw, "scripted")
        assert outcome.success and outcome.success_once, raw["task"]["pickup_obj_name"]


def test_scripted_returns_chunks_without_images(episodes):
    plugins = get_plugins()
    spec = EpisodeSpec.model_validate(episodes[0])
    policy = plugins.policy("scripted").factory({"name": "scripted", "chunk": 5})
    assert policy.needs_images is False
    env = build_env(spec, Timing(), plugins)
    try:
        env.reset(0)
        policy.reset(EpisodeContext(spec=spec, episode_index=0, seed=0, prompt="", move_groups=env.move_groups,
                                    policy_dt_s=0.066, env=env))
        chunk = policy.act(env.observe(images=False))
        assert chunk["arm"].shape == (5, 7) and chunk["gripper"].shape == (5, 1)
        assert np.all(chunk["gripper"] == 0.0)  # open while approaching
    finally:
        env.close()


def test_scripted_needs_privileged_env(episodes):
    spec = EpisodeSpec.model_validate(episodes[0])
    policy = get_plugins().policy("scripted").factory({})
    with pytest.raises(ValueError, match="privileged"):
        policy.reset(EpisodeContext(spec=spec, episode_index=0, seed=0, prompt="", move_groups={"arm": 7, "gripper": 1},
                                    policy_dt_s=0.066))


def test_random_is_seeded_and_fails(episodes):
    a, qa = _run(episodes[0], "random")
    b, qb = _run(episodes[0], "random")
    assert np.array_equal(qa, qb)  # same episode seed, same rollout
    assert not a.success and not a.success_once
