"""The MetaWorld env suite against LeRobot's own MetaWorld evaluation (``lerobot-eval --env.type=metaworld``).

Both sides run here (metaworld shares the main venv). Ours is what a ``molmo-eval benchmark=metaworld_<task>``
worker plays: the planned episodes as plans, each a ``SuiteSession`` over ``MetaWorldSuite``, played by our rollout
loop, a recorder asking for every step's frame. Theirs is LeRobot's: ``make_env`` over its ``metaworld`` config, its
env processors and ``lerobot_eval.rollout``, episode ``k`` seeded ``seed + k``. Two policies: a seeded uniform
random action in [-1, 1]⁴, and MetaWorld's scripted expert of the task (ours: ``policy=scripted``; theirs: the class
LeRobot's ``TASK_POLICY_MAPPING`` names, on the 39-D observation its env formatted). Every episode must agree on
success (any step's ``is_success`` up to the first done) and step count, and bit for bit on every step's reward
and every observation the policy was shown (4-D state, 480² image). LeRobot's step limit is its env's
``_max_episode_steps`` (500, not ``--env.episode_length``), so the short episodes set that attribute.
The default run plays 2 short random episodes; ``-m slow`` 20 episodes (:data:`SLOW_RUNS`), 12 of them the experts'
(each successful).
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
from molmo_lerobot.policies.factory import make_policy
from molmo_lerobot.recording import Recorder
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.suites import metaworld
from molmo_lerobot.suites.benchmark import suite_plan

pytest.importorskip("metaworld")


def random_action(seed: int, step: int) -> np.ndarray:
    """A seeded uniform random action (float32, as a LeRobot policy's tensor)."""
    return np.random.default_rng([seed, step]).uniform(-1.0, 1.0, metaworld.ACTION_DIM).astype(np.float32)


def _digest(img: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(img, dtype=np.uint8).tobytes()).hexdigest()


def lerobot_episodes(task: str, policy: str, seed: int, episodes: int, horizon: int, monkeypatch) -> list[dict]:
    """LeRobot's side: ``lerobot-eval --env.type=metaworld --env.task=<task> --eval.batch_size=1``."""
    import torch
    from lerobot.envs import metaworld as lerobot_metaworld
    from lerobot.envs.configs import MetaworldEnv
    from lerobot.envs.factory import make_env
    from lerobot.processor import PolicyProcessorPipeline
    from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action
    from lerobot.scripts.lerobot_eval import rollout as lerobot_rollout

    formatted = lerobot_metaworld.MetaworldEnv._format_raw_obs
    raw: list[np.ndarray] = []

    def keep_raw(self, raw_obs):  # the expert acts on the 39-D observation the env formats
        raw.append(raw_obs)
        return formatted(self, raw_obs)

    monkeypatch.setattr(lerobot_metaworld.MetaworldEnv, "_format_raw_obs", keep_raw)

    class Recorded(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.seed, self.shown, self.expert = 0, [], lerobot_metaworld.TASK_POLICY_MAPPING[task]()

        def reset(self) -> None:
            self.shown = []

        def select_action(self, obs: dict) -> torch.Tensor:
            img = (obs["observation.image"][0] * 255).round().to(torch.uint8).permute(1, 2, 0).numpy()
            self.shown.append((obs["observation.state"][0].numpy().tolist(), _digest(img)))
            if policy == "expert":
                action = np.asarray(self.expert.get_action(raw[-1]), dtype=np.float32)
            else:
                action = random_action(self.seed, len(self.shown) - 1)
            return torch.from_numpy(action)[None]

    cfg = MetaworldEnv(task=task)
    [[env]] = [group.values() for group in make_env(cfg, n_envs=1).values()]
    for sub in env.envs:
        sub.unwrapped._max_episode_steps = horizon
    env_pre, env_post = cfg.get_env_processors()
    pre = PolicyProcessorPipeline(steps=[])
    post = PolicyProcessorPipeline(steps=[], to_transition=policy_action_to_transition,
                                   to_output=transition_to_policy_action)
    rec, out = Recorded(), []
    try:
        for k in range(episodes):
            rec.seed = seed + k
            data = lerobot_rollout(env, rec, env_pre, env_post, pre, post, seeds=[seed + k])
            first = int(torch.argmax(data["done"][0].to(int)))
            out.append({"success": bool(data["success"][0][: first + 1].any()), "steps": first + 1,
                        "rewards": data["reward"][0][: first + 1].tolist(), "shown": rec.shown})
    finally:
        env.close()
    return out


class Replayed(Policy):
    """:func:`random_action` as a molmo-eval policy, one step per chunk."""

    needs_images = False

    def __init__(self) -> None:
        self.seed, self.steps = 0, 0

    def reset(self, ctx) -> None:
        self.seed, self.steps = ctx.seed, 0

    def act(self, obs):
        self.steps += 1
        return {metaworld.MOVE_GROUP: random_action(self.seed, self.steps - 1)[None]}


class Shown(Recorder):
    """Every step's observation as the policy was shown it (state, image digest) and the reward after it."""

    def start_episode(self, info) -> None:
        self.shown, self.rewards = [], []

    def record_step(self, obs, action, reward, success, done) -> None:
        self.shown.append((np.asarray(obs["qpos"][metaworld.MOVE_GROUP]).tolist(),
                           _digest(obs["images"][metaworld.CAMERA])))
        self.rewards.append(reward)

    def end_episode(self, result) -> None:
        pass


def our_episodes(task: str, policy: str, seed: int, episodes: int, horizon: int) -> list[dict[str, Any]]:
    """Our side: ``molmo-eval benchmark=metaworld_<task> policy=<random|scripted> seed=… horizon=…``'s episodes."""
    config = RunConfig.of(compose([f"policy={'scripted' if policy == 'expert' else 'random'}",
                                   f"benchmark=metaworld_{task}", f"seed={seed}", f"horizon={horizon}",
                                   f"benchmark.episodes_per_task={episodes}"]))
    bench = run_kind(Plugins(), config).benchmark_of(config)
    agent = make_policy(Plugins(), dict(config.plain()["policy"])) if policy == "expert" else Replayed()
    sessions, out = run_kind(Plugins(), config).sessions_of(config), []
    try:
        for i, episode in enumerate(bench.episodes):
            session = sessions.open(suite_plan(i, bench.suite, episode, True), agent, end_on_success=False)
            shown = Shown()
            shown.start_episode(None)
            result = rollout(session, agent, [shown], "parity")
            out.append({"success": result.success, "steps": result.steps, "rewards": shown.rewards,
                        "shown": shown.shown})
    finally:
        sessions.close()
        agent.close()
    return out


def compare(task: str, policy: str, seed: int, episodes: int, horizon: int, monkeypatch) -> list[tuple]:
    """Both sides' episodes, checked equal; per episode (task, policy, seed, success, steps)."""
    theirs = lerobot_episodes(task, policy, seed, episodes, horizon, monkeypatch)
    ours = our_episodes(task, policy, seed, episodes, horizon)
    assert len(theirs) == len(ours) == episodes
    for k, (t, o) in enumerate(zip(theirs, ours, strict=True)):
        where = f"{task} {policy} episode {k} (seed {seed + k})"
        assert (o["success"], o["steps"]) == (t["success"], t["steps"]), where
        assert o["rewards"] == t["rewards"], f"{where}: rewards differ"
        assert len(o["shown"]) == len(t["shown"]) == o["steps"], where
        for step, (a, b) in enumerate(zip(o["shown"], t["shown"], strict=True)):
            assert a == b, f"{where}, step {step}: observation differs (state {a[0]} vs {b[0]})"
    return [(task, policy, seed + k, t["success"], t["steps"]) for k, t in enumerate(theirs)]


def test_metaworld_constants_are_lerobots():
    from lerobot.envs import metaworld as lerobot_metaworld
    from lerobot.envs.configs import MetaworldEnv

    cfg = MetaworldEnv()
    assert cfg.fps == metaworld.CONTROL_HZ and tuple(cfg.features["action"].shape) == (metaworld.ACTION_DIM,)
    assert tuple(cfg.features["agent_pos"].shape) == (metaworld.STATE_DIM,)
    assert tuple(cfg.features["pixels/top"].shape) == (metaworld.IMAGE_SIZE, metaworld.IMAGE_SIZE, 3)
    env = lerobot_metaworld.MetaworldEnv("reach-v3")
    assert env._max_episode_steps == metaworld.MAX_STEPS and env.camera_name == metaworld.CAMERA_NAME
    assert metaworld.task_names() == [t for g in metaworld.GROUPS for t in lerobot_metaworld.DIFFICULTY_TO_TASKS[g]]
    assert set(metaworld.task_names()) == set(lerobot_metaworld.TASK_DESCRIPTIONS)
    env.close()


def test_metaworld_matches_lerobot_eval(monkeypatch):
    compare("push-v3", "random", seed=1000, episodes=2, horizon=4, monkeypatch=monkeypatch)


#: the slow run: 12 expert episodes (each successful) on three tasks whose experts finish in ~40 steps, 8 random
SLOW_RUNS = [("handle-press-side-v3", "expert", 4, metaworld.MAX_STEPS), ("coffee-button-v3", "expert", 4,
             metaworld.MAX_STEPS), ("handle-press-v3", "expert", 4, metaworld.MAX_STEPS), ("push-v3", "random", 8, 15)]


@pytest.mark.slow
@pytest.mark.timeout(3600)  # LeRobot's env draws 480² every step: ~0.5-1 s a step a side on this loaded machine
@pytest.mark.parametrize(("task", "policy", "episodes", "horizon"), SLOW_RUNS)
def test_metaworld_matches_lerobot_eval_on_expert_and_random_episodes(monkeypatch, task, policy, episodes, horizon):
    rows = compare(task, policy, 0, episodes, horizon, monkeypatch)
    assert policy != "expert" or all(row[3] for row in rows), rows  # every expert episode succeeds
    print("\ntask policy seed success steps")
    for row in rows:
        print(*row)


def policy_parity(tmp_path, monkeypatch, task: str, seed: int, episodes: int, horizon: int) -> list[dict[str, Any]]:
    """A tiny ACT at random init with MetaWorld's features through LeRobot's ``eval_policy`` and through
    ``molmo-eval policy=lerobot``: the same action at every step, the same outcomes."""
    from lerobot.envs.configs import MetaworldEnv
    from lerobot_policy_reference import lerobot_eval_episodes, make_lerobot_env
    from policy_parity import assert_same_episodes, molmo_policy, play_session
    from tiny_policies import save_act

    checkpoint = save_act(tmp_path / "act", "metaworld", metaworld.IMAGE_SIZE)
    cfg = MetaworldEnv(task=task)
    env = make_lerobot_env(cfg)
    for sub in env.envs:  # LeRobot's step limit is the env's attribute (500), not --env.episode_length
        monkeypatch.setattr(sub.unwrapped, "_max_episode_steps", horizon)
    try:
        theirs = lerobot_eval_episodes(cfg, env, checkpoint, seed, episodes)
    finally:
        env.close()
    config = RunConfig.of(compose(["policy=random", f"benchmark=metaworld_{task}", f"seed={seed}",
                                   f"horizon={horizon}", f"benchmark.episodes_per_task={episodes}"]))
    bench = run_kind(Plugins(), config).benchmark_of(config)
    policy, sessions = molmo_policy(checkpoint), run_kind(Plugins(), config).sessions_of(config)
    try:
        ours = [play_session(sessions.open(suite_plan(i, bench.suite, e, True), policy, end_on_success=True),
                             policy, metaworld.MOVE_GROUP) for i, e in enumerate(bench.episodes)]
    finally:
        sessions.close()
        policy.close()
    assert_same_episodes(ours, theirs, f"metaworld {task} act")
    return theirs


def test_metaworld_act_actions_are_lerobot_evals(tmp_path, monkeypatch):
    policy_parity(tmp_path, monkeypatch, "reach-v3", seed=1000, episodes=1, horizon=5)  # two ACT chunks
