"""The PushT env suite against LeRobot's own PushT evaluation (``lerobot-eval --env.type=pusht``).

Both sides run here (gym_pusht shares the main venv). Ours is what a ``molmo-eval benchmark=pusht`` worker plays:
the benchmark's planned episodes (``load_suite_benchmark``) as plans, each a ``SuiteSession`` over
``PushTSuite`` played by our rollout loop. Theirs is LeRobot's: ``make_env`` over its ``pusht`` config, the env
processors that config gives, ``lerobot_eval.rollout`` with episode ``k`` seeded ``seed + k`` (``eval_policy``
with ``--eval.batch_size=1``). For a seeded random policy and a fixed replay every episode must agree on success
(any step's ``is_success`` up to the first done, ``eval_policy``'s rule) and step count, and bit for bit on every
step's reward (to 1e-12: gym_pusht's coverage varies in its last bit, see ``_compare``) and bit for bit on every
observation the policy was shown (agent position, image). The default run plays
short episodes; ``-m slow`` plays full-length ones (LeRobot's 300 steps).
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np
import pytest

from molmo_lerobot.benchmark_kinds import run_kind
from molmo_lerobot.config import compose
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import Policy
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.suites import pusht
from molmo_lerobot.suites.benchmark import suite_plan

pytest.importorskip("gym_pusht")


def random_target(seed: int, step: int) -> np.ndarray:
    """A seeded uniform random target position in the workspace (float32, as a LeRobot policy's tensor)."""
    return np.random.default_rng([seed, step]).uniform(0.0, 512.0, 2).astype(np.float32)


def replay_target(seed: int, step: int) -> np.ndarray:
    """A fixed open-loop sweep through the middle of the workspace, where it pushes the block about."""
    t = float(step)
    return np.asarray([256 + 180 * np.sin(0.09 * t), 256 + 160 * np.cos(0.07 * t)], dtype=np.float32)


POLICIES = {"random": random_target, "replay": replay_target}


def _digest(img: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(img, dtype=np.uint8).tobytes()).hexdigest()


def lerobot_episodes(policy: str, seed: int, episodes: int, horizon: int) -> list[dict[str, Any]]:
    """LeRobot's side: ``lerobot-eval --env.type=pusht --env.episode_length=<horizon> --eval.batch_size=1``."""
    import torch
    from lerobot.envs.configs import PushtEnv
    from lerobot.envs.factory import make_env
    from lerobot.processor import PolicyProcessorPipeline
    from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action
    from lerobot.scripts.lerobot_eval import rollout as lerobot_rollout

    class Recorded(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.seed, self.shown = 0, []

        def reset(self) -> None:
            self.shown = []

        def select_action(self, obs: dict) -> torch.Tensor:
            img = (obs["observation.image"][0] * 255).round().to(torch.uint8).permute(1, 2, 0).numpy()
            self.shown.append((obs["observation.state"][0].numpy().tolist(), _digest(img)))
            return torch.from_numpy(POLICIES[policy](self.seed, len(self.shown) - 1))[None]

    cfg = PushtEnv(episode_length=horizon)
    env = make_env(cfg, n_envs=1)["pusht"][0]
    env_pre, env_post = cfg.get_env_processors()
    pre = PolicyProcessorPipeline(steps=[])
    post = PolicyProcessorPipeline(steps=[], to_transition=policy_action_to_transition,
                                   to_output=transition_to_policy_action)
    rec, out = Recorded(), []
    for k in range(episodes):
        rec.seed = seed + k
        data = lerobot_rollout(env, rec, env_pre, env_post, pre, post, seeds=[seed + k])
        first = int(torch.argmax(data["done"][0].to(int)))
        out.append({"success": bool(data["success"][0][: first + 1].any()), "steps": first + 1,
                    "rewards": data["reward"][0][: first + 1].tolist(), "shown": rec.shown})
    env.close()
    return out


class Replayed(Policy):
    """A policy of :data:`POLICIES` as a molmo-eval policy, one step per chunk, remembering what it saw."""

    needs_images = True

    def __init__(self, target) -> None:
        self.target, self.seed, self.shown = target, 0, []

    def reset(self, ctx) -> None:
        self.seed, self.shown = ctx.seed, []

    def act(self, obs):
        self.shown.append((np.asarray(obs["qpos"][pusht.MOVE_GROUP]).tolist(), _digest(obs["images"][pusht.CAMERA])))
        return {pusht.MOVE_GROUP: self.target(self.seed, len(self.shown) - 1)[None]}


def _logging_step(suite: pusht.PushTSuite, rewards: list[float]):
    """``suite.step`` that also appends each step's reward to ``rewards``."""
    step = type(suite).step

    def logged(action, images=True):
        reply = step(suite, action, images)
        rewards.append(reply["reward"])
        return reply

    return logged


def our_episodes(policy: str, seed: int, episodes: int, horizon: int) -> list[dict[str, Any]]:
    """Our side: ``molmo-eval benchmark=pusht seed=<seed> horizon=<horizon>``'s episodes, as a worker plays them."""
    config = RunConfig.of(compose(["policy=random", "benchmark=pusht", f"seed={seed}", f"horizon={horizon}",
                                   f"benchmark.episodes_per_task={episodes}"]))
    bench = run_kind(Plugins(), config).benchmark_of(config)
    sessions, agent, out = run_kind(Plugins(), config).sessions_of(config), Replayed(POLICIES[policy]), []
    try:
        for i, episode in enumerate(bench.episodes):
            session = sessions.open(suite_plan(i, bench.suite, episode, True), agent, end_on_success=False)
            rewards: list[float] = []
            session.suite.step = _logging_step(session.suite, rewards)
            result = rollout(session, agent, [], "parity")
            del session.suite.step  # the class's own again
            out.append({"success": result.success, "steps": result.steps, "rewards": rewards, "shown": agent.shown})
    finally:
        sessions.close()
    return out


def _compare(policy: str, seed: int, episodes: int, horizon: int) -> list[tuple]:
    """Both sides' episodes, checked equal; per episode (policy, seed, success, steps, best reward, steps whose
    rewards are not bit-identical)."""
    theirs, ours = lerobot_episodes(policy, seed, episodes, horizon), our_episodes(policy, seed, episodes, horizon)
    assert len(theirs) == len(ours) == episodes
    for k, (t, o) in enumerate(zip(theirs, ours, strict=True)):
        where = f"{policy} episode {k} (seed {seed + k})"
        assert (o["success"], o["steps"]) == (t["success"], t["steps"]), where
        assert o["rewards"] and len(o["rewards"]) == len(t["rewards"]), where
        # to the last bit but one: gym_pusht builds the goal's shape from a Python set of the block's two shapes,
        # whose order follows memory addresses, so even one env reset twice alike can differ there
        assert np.allclose(o["rewards"], t["rewards"], rtol=0, atol=1e-12), f"{where}: rewards differ"
        assert len(o["shown"]) == len(t["shown"]) == o["steps"], where
        for step, (a, b) in enumerate(zip(o["shown"], t["shown"], strict=True)):
            assert a == b, f"{where}, step {step}: observation differs (state {a[0]} vs {b[0]})"
    return [(policy, seed + k, t["success"], t["steps"], round(max(t["rewards"]), 4),
             sum(a != b for a, b in zip(o["rewards"], t["rewards"], strict=True)))
            for k, (t, o) in enumerate(zip(theirs, ours, strict=True))]


def test_pusht_constants_are_lerobots():
    from lerobot.envs.configs import PushtEnv

    cfg = PushtEnv()
    assert (cfg.episode_length, cfg.fps) == (pusht.MAX_STEPS, pusht.CONTROL_HZ)
    assert f"{cfg.package_name}/{cfg.task}" == pusht.ENV_ID
    assert tuple(cfg.features["action"].shape) == (pusht.ACTION_DIM,)


@pytest.mark.parametrize("policy", ["random", "replay"])
def test_pusht_matches_lerobot_eval(policy):
    _compare(policy, seed=1000, episodes=2, horizon=30)


@pytest.mark.slow
def test_pusht_matches_lerobot_eval_full_episodes():
    rows = [row for policy in POLICIES for row in _compare(policy, seed=0, episodes=10, horizon=pusht.MAX_STEPS)]
    print("\npolicy seed success steps best_reward rewards_not_bit_identical")
    for row in rows:
        print(*row)
