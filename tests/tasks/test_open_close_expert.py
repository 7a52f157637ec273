"""The scripted open/close expert through the one rollout loop (one episode per task type, a few seconds)."""

from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.articulated.generate import generate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.policies.scripted import ScriptedExpert
from molmo_lerobot.runner.episode import EpisodeSession
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.plan import plan_spec, resolve_horizon
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.sim.env import Timing


def _run(raw: dict, policy, control: str | None = None) -> tuple[bool, float]:
    run = RunContext.build()
    plugins = run.plugins
    timing = Timing() if control is None else Timing(control=control)
    spec = parse_episode(raw, plugins)
    task_type = plugins.task_type(spec.task_name)
    env = build_env(spec, timing, run)
    try:
        env.reset(spec.seed)
        task = task_type.create(spec, env)
        horizon = resolve_horizon(None, spec.task, task_type.default_horizon_sec, timing.policy_dt_ms)
        plan = plan_spec(spec, run.plugins, seed=spec.seed, horizon=horizon)
        out = rollout(EpisodeSession.start(plan, spec, env, task, run, policy=policy), policy, [], "scripted")
        return out.success, task.fraction()
    finally:
        env.close()


def _episodes(task: str, n_houses: int, seed: int, uid_prefix: str) -> list[dict]:
    return [e for e in generate_benchmark(task, n_houses, 1, seed, "t")[0]
            if e["task"]["pickup_obj_name"].startswith(uid_prefix)]


@pytest.mark.parametrize("control", ["hold", "ramp"])
def test_expert_opens_the_microwave(control):
    """Under MolmoSpaces' hold too: a target change the shoulder cannot follow without saturating
    its actuator made the arm chatter and the handle slip out of the fingers."""
    raw = _episodes("open", 12, 1, "kitchen_microwave")[0]
    success, fraction = _run(raw, ScriptedExpert({}), control)
    assert success and fraction >= 0.3


def test_timing_defaults_to_molmospaces_hold():
    assert Timing().control == "hold"


def test_expert_closes_a_drawer():
    raw = _episodes("close", 3, 0, "drawer_chest")[0]
    success, fraction = _run(raw, ScriptedExpert({}))
    assert success and fraction <= 0.1


@pytest.mark.slow
@pytest.mark.parametrize("task", ["open", "close"])
def test_expert_on_every_object_kind(task):
    seen: dict[str, bool] = {}
    for raw in generate_benchmark(task, 12, 1, 3, "t")[0]:
        kind = raw["task"]["joint_name"]
        if kind not in seen:
            seen[kind] = _run(raw, ScriptedExpert({}))[0]
    assert seen and all(seen.values()), seen


def test_moves_in_contact_keep_each_step_within_what_the_arm_follows():
    """A path in contact (``gentle``) is one move through its via-points, no joint target changing
    by more than CONTACT_STEP a step; a free move may take larger steps."""
    from molmo_lerobot.policies.expert_motion import CONTACT_STEP
    from molmo_lerobot.policies.scripted_articulated import ScriptedArticulated

    def queued(gentle: bool) -> np.ndarray:
        expert = ScriptedArticulated({})
        expert.dt, expert.queue, expert.q_cmd, expert.g_cmd = 0.066, [], np.zeros(7), 1.0
        waypoints = [np.array([0.4 * k, -0.3 * k, 0.1, 0, 0, 0.05 * k, 0]) for k in range(1, 6)]
        expert._path(waypoints, 1.0, 1.0, gentle=gentle)
        return np.array([np.zeros(7)] + [a["arm"] for a in expert.queue])

    gentle, free = queued(True), queued(False)
    assert np.allclose(gentle[-1], free[-1]) and np.allclose(gentle[-1], [2.0, -1.5, 0.1, 0, 0, 0.25, 0])
    assert np.abs(np.diff(gentle, axis=0)).max() <= CONTACT_STEP + 1e-9
    assert np.abs(np.diff(free, axis=0)).max() > CONTACT_STEP
    assert np.all(np.diff(gentle[:, 0]) > 0)  # never stops at a via-point
