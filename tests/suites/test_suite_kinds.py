"""One ``SuiteSession`` for every env suite: what it takes from each suite's ``SuiteKind``.

LIBERO's env needs its own venv, so here its session plays over a stand-in with LIBERO's reply shapes (the
session's plumbing, not LIBERO, is under test; ``test_libero_*`` run the real one where the venv exists).
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from molmo_lerobot.suites import libero
from molmo_lerobot.suites.benchmark import SuiteSession, suite_plan
from molmo_lerobot.suites.plugin import LIBERO, METAWORLD, PUSHT


class LiberoStandIn:
    """Replies as ``LiberoSuite`` does; success at the third step."""

    def __init__(self) -> None:
        self.actions: list[np.ndarray] = []

    def reset(self, episode):
        return self._obs()

    def step(self, action, images=True):
        self.actions.append(action)
        done = len(self.actions) == 3
        return {"observation": self._obs(), "reward": float(done), "terminated": done, "success": done}

    def _obs(self):
        img = np.zeros((8, 8, 3), np.uint8)
        return {"observation.images.image": img, "observation.images.image2": img,
                "observation.state": np.arange(8, dtype=np.float64)}


def test_libero_session_keeps_libero_conventions():
    [episode] = libero.plan_episodes("libero_object", [{"task_id": 3, "init_states": 50, "instruction": "pick"}], 1,
                                     seed=7, horizon=10)
    plan = suite_plan(0, LIBERO, episode, False)
    assert plan.kind == "libero" and plan.task_type == "libero_object/task_03"
    suite = LiberoStandIn()
    session = SuiteSession(LIBERO, plan, suite, 8, end_on_success=False)
    assert session.episode == episode
    ctx = session.policy_context()
    assert ctx.move_groups == {"eef": 7} and ctx.extra == {"delta_groups": ["eef"], "camera_features": {
        "image": "observation.images.image", "image2": "observation.images.image2"}} and ctx.policy_dt_s == 1 / 20
    obs = session.observe()
    assert sorted(obs["images"]) == ["image", "image2"] and obs["qpos"]["eef"].shape == (8,)
    ended = None
    while ended is None:
        session.step({"eef": np.full(7, 0.5)})
        ended = session.end()
    result = session.result()
    assert (result.success, result.steps, result.extra["ended_by"]) == (True, 3, "success")
    assert {k: result.extra[k] for k in ("suite", "task_id", "init_state_index", "digest")} == {
        "suite": "libero_object", "task_id": 3, "init_state_index": 0, "digest": episode.digest}
    assert suite.actions[0].shape == (7,)


def test_every_suite_kind_plans_what_it_reads_back():
    for kind in (LIBERO, PUSHT, METAWORLD):
        tasks = [{"task_id": 0, "task": "T", "group": "g", "init_states": 2, "instruction": ""}]
        suite = "libero_goal" if kind is LIBERO else kind.name
        episodes = kind.plan(suite, tasks, 2, seed=5, horizon=4)
        assert [e.seed for e in episodes] == [5, 6]
        for i, episode in enumerate(episodes):
            plan = suite_plan(i, kind, episode, True)
            assert plan.kind == kind.name and plan.digest == episode.digest and plan.spec == asdict(episode)
            assert SuiteSession(kind, plan, _Replying(kind), 8, end_on_success=False).episode == episode


class _Replying:
    """A suite env whose reset replies nothing (the session reads the episode back from the plan)."""

    def __init__(self, kind) -> None:
        self.kind = kind

    def reset(self, episode):
        return {}
