"""The place expert through the real rollout loop: one episode per pick-and-place task type."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.tabletop.generate import generate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.scripted_place import ScriptedPlace
from molmo_lerobot.runner.episode import EpisodeSession
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.plan import plan_spec
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.sim.env import Timing

HORIZON = 220  # the script takes about 150 policy steps; the rest checks that the result lasts


def _run(raw: dict, policy_name: str, horizon: int = HORIZON):
    run = RunContext.build()
    plugins = run.plugins
    spec = parse_episode(raw, plugins)
    timing = Timing()
    policy = plugins.policy(policy_name).factory({"name": policy_name})
    env = build_env(spec, timing, run)
    try:
        env.reset(spec.seed)
        task = plugins.task_type(spec.task_name).create(spec, env)
        plan = plan_spec(spec, run.plugins, seed=spec.seed, horizon=horizon)
        return rollout(EpisodeSession.start(plan, spec, env, task, run, policy=policy), policy, [], policy_name), policy
    finally:
        env.close()


@pytest.mark.parametrize("task", ["pick_and_place", "pick_and_place_next_to", "pick_and_place_color"])
def test_expert_solves_an_episode(task):
    raw = generate_benchmark(task, 1, 1, 5, "test")[0][0]
    assert Plugins().expert(Plugins().task_type(task).name).factory is ScriptedPlace
    outcome, policy = _run(raw, "scripted")
    assert isinstance(policy.current, ScriptedPlace)
    assert outcome.success, raw["language"]["task_description"]


def test_random_does_not_place():
    raw = generate_benchmark("pick_and_place", 1, 1, 5, "test")[0][0]
    outcome, _ = _run(raw, "random", horizon=100)
    assert not outcome.success_once


def test_expert_carries_lower_when_the_clearing_height_is_out_of_reach(monkeypatch):
    """Where the arm cannot lift the object as high as clearing every other object needs (IK fails
    above a ceiling), the expert carries it lower instead of failing the episode (pick_and_place_v2
    episode 5 was such an error)."""
    import molmo_lerobot.policies.scripted_place as place

    monkeypatch.setattr(place, "CARRY_CLEARANCE", 0.30)  # a lift the ceiling below refuses
    plan = ScriptedPlace._plan
    ceilings = []

    def plan_with_ceiling(self, phase):
        if phase == "carry" and not ceilings:
            ceilings.append(self._tcp()[2, 3] + 0.08)
            solve = self.ik.solve
            monkeypatch.setattr(self.ik, "solve", lambda T, q: None if T[2, 3] > ceilings[0] else solve(T, q))
        plan(self, phase)

    monkeypatch.setattr(ScriptedPlace, "_plan", plan_with_ceiling)
    raw = generate_benchmark("pick_and_place", 1, 1, 5, "test")[0][0]
    outcome, _ = _run(raw, "scripted")
    assert ceilings and outcome.success, raw["language"]["task_description"]
