"""The ALOHA env suite against LeRobot's own ALOHA evaluation (``lerobot-eval --env.type=aloha``).

LeRobot's side is ``lerobot_aloha_reference.py`` in the ALOHA venv (``make_env`` over its ``AlohaEnv`` config, its
env processors, ``lerobot_eval.rollout`` / ``eval_policy``, episode ``k`` seeded ``seed + k``). Ours is what a
``molmo-eval benchmark=aloha_*`` worker plays: the planned episodes as plans, each a ``SuiteSession`` over
``AlohaSuite`` (whose server draws only the observed camera) played by our rollout loop. For a seeded random policy
and a fixed replay every episode must agree on success, step count and every step's reward, and bit for bit on every
observation the policy was shown (14-D state, top image, task); and a tiny ACT at random init saved with ALOHA's
features (``tiny_policies.py``) must hand the env the same action at every step through ``eval_policy`` as through
``policy=lerobot``. The default run plays a few short episodes of AlohaInsertion-v0; ``-m slow`` plays 20 episodes
over both tasks and both policies.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from lerobot_aloha_reference import POLICIES
from policy_parity import assert_same_episodes, molmo_policy, play_session
from tiny_policies import save_act

from molmo_lerobot.policies.base import Policy
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.suites import aloha
from molmo_lerobot.suites.benchmark import SuiteSession, suite_plan
from molmo_lerobot.suites.plugin import ALOHA

HERE = Path(__file__).parent
FRAME = (aloha.IMAGE_HEIGHT, aloha.IMAGE_WIDTH)
BENCHMARK = {task: name for name, task in aloha.TASKS.items()}


@pytest.fixture(scope="module")
def venv() -> Path:
    path = aloha.aloha_venv()
    if not (path / "bin" / "python").exists():
        pytest.skip(f"no ALOHA venv at {path} (build it: make .aloha-venv)")
    return path


@pytest.fixture(scope="module")
def suite(venv):
    """One ALOHA env process for the module's tests."""
    with aloha.AlohaSuite(venv) as proc:
        yield proc


def reference(venv: Path, task: str, horizon: int, env: dict | None = None, runs: tuple[dict, ...] = ()) -> dict:
    """``lerobot_aloha_reference.py``'s document, run in the ALOHA venv."""
    args = {"task": task, "horizon": horizon, "env": env, "runs": list(runs)}
    proc = subprocess.run([str(venv / "bin" / "python"), str(HERE / "lerobot_aloha_reference.py"), json.dumps(args)],
                          env={**os.environ, "MUJOCO_GL": "egl"}, capture_output=True, text=True, timeout=7200)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    assert proc.returncode == 0 and lines, proc.stdout[-2000:] + proc.stderr[-3000:]
    return json.loads(lines[-1])


class Replayed(Policy):
    """A policy of :data:`POLICIES` as a molmo-eval policy, one step per chunk, remembering what it was shown."""

    needs_images = True

    def __init__(self, name: str) -> None:
        self.target, self.seed, self.shown = POLICIES[name], 0, []

    def reset(self, ctx) -> None:
        self.seed, self.shown = ctx.seed, []

    def act(self, obs):
        image = np.ascontiguousarray(obs["images"][aloha.CAMERA], dtype=np.uint8)
        self.shown.append({"state": np.asarray(obs["qpos"][aloha.MOVE_GROUP]).tolist(), "task": obs["prompt"],
                           "image": hashlib.sha256(image.tobytes()).hexdigest()})
        return {aloha.MOVE_GROUP: self.target(self.seed, len(self.shown) - 1)[None]}


class Rewards:
    """The suite, each step's reward noted."""

    def __init__(self, suite: aloha.AlohaSuite) -> None:
        self.suite, self.rewards = suite, []

    def reset(self, episode):
        self.rewards = []
        return self.suite.reset(episode)

    def step(self, action, images=True):
        reply = self.suite.step(action, images)
        self.rewards.append(reply["reward"])
        return reply


def planned(suite: aloha.AlohaSuite, task: str, episodes: int, seed: int, horizon: int) -> list[aloha.AlohaEpisode]:
    """``molmo-eval benchmark=<task's> seed=<seed> horizon=<horizon>``'s first ``episodes`` episodes."""
    name = BENCHMARK[task]
    return aloha.plan_episodes(name, suite.tasks(name), episodes, seed=seed, horizon=horizon)


def our_env_episodes(suite: aloha.AlohaSuite, task: str, policy: str, seed: int, episodes: int,
                     horizon: int) -> list[dict[str, Any]]:
    agent, logged, out = Replayed(policy), Rewards(suite), []
    for i, episode in enumerate(planned(suite, task, episodes, seed, horizon)):
        session = SuiteSession(ALOHA, suite_plan(i, ALOHA, episode, True), logged, FRAME, end_on_success=True)
        agent.reset(session.policy_context())
        result = rollout(session, agent, [], "parity")
        out.append({"success": result.success, "steps": result.steps, "rewards": logged.rewards,
                    "shown": agent.shown})
    return out


def assert_same_env_episodes(ours: list[dict], theirs: list[dict], where: str) -> None:
    assert len(ours) == len(theirs), where
    for k, (o, t) in enumerate(zip(ours, theirs, strict=True)):
        label = f"{where} episode {k}"
        assert (o["success"], o["steps"]) == (t["success"], t["steps"]), label
        assert o["rewards"] == t["rewards"], f"{label}: rewards differ"
        assert len(o["shown"]) == len(t["shown"]) == o["steps"], label
        for step, (a, b) in enumerate(zip(o["shown"], t["shown"], strict=True)):
            assert a == b, f"{label}, step {step}: observation differs (state {a['state']} vs {b['state']})"


def our_policy_episodes(suite: aloha.AlohaSuite, checkpoint: Path, task: str, seed: int, episodes: int,
                        horizon: int) -> list[dict[str, Any]]:
    """``molmo-eval policy=lerobot policy.path=<checkpoint>``'s episodes on ``suite``."""
    policy, out = molmo_policy(checkpoint), []
    try:
        for i, episode in enumerate(planned(suite, task, episodes, seed, horizon)):
            session = SuiteSession(ALOHA, suite_plan(i, ALOHA, episode, True), suite, FRAME, end_on_success=True)
            policy.reset(session.policy_context())
            out.append(play_session(session, policy, aloha.MOVE_GROUP))
    finally:
        policy.close()
    return out


def test_aloha_constants_are_lerobots():
    from lerobot.envs.configs import AlohaEnv

    for task in aloha.TASKS.values():
        cfg = AlohaEnv(task=task)
        assert (cfg.episode_length, cfg.fps, cfg.obs_type) == (aloha.MAX_STEPS, aloha.CONTROL_HZ, "pixels_agent_pos")
        assert (cfg.observation_height, cfg.observation_width) == FRAME
        assert tuple(cfg.features["action"].shape) == (aloha.ACTION_DIM,)
        assert tuple(cfg.features["agent_pos"].shape) == (aloha.STATE_DIM,)
        assert cfg.features_map["pixels/top"] == "observation.images.top"
        assert cfg.gym_kwargs == {"obs_type": "pixels_agent_pos", "render_mode": "rgb_array", "max_episode_steps": 400}


@pytest.fixture(scope="module")
def short_insertion(venv, tmp_path_factory) -> tuple[Path, dict]:
    """LeRobot's side of the default tests, in one run of the reference (LeRobot's env draws three cameras a step,
    ~0.3 s or more here): two 6-step replay episodes and one 6-step episode of the tiny ACT (chunks of 4: two
    inferences) on AlohaInsertion-v0."""
    checkpoint = save_act(tmp_path_factory.mktemp("aloha") / "act", "aloha", FRAME)
    doc = reference(venv, "AlohaInsertion-v0", 6, env={"policy": "replay", "seed": 1000, "episodes": 2},
                    runs=({"checkpoint": str(checkpoint), "seed": 3, "episodes": 1},))
    return checkpoint, doc


def test_short_episodes_match_lerobot_eval(short_insertion, suite):
    _, doc = short_insertion
    ours = our_env_episodes(suite, "AlohaInsertion-v0", "replay", seed=1000, episodes=2, horizon=6)
    assert_same_env_episodes(ours, doc["env"], "AlohaInsertion-v0 replay")
    assert ours[0]["shown"][0]["task"] == "insertion"


def test_a_tiny_act_acts_as_under_lerobot_eval(short_insertion, suite):
    checkpoint, doc = short_insertion
    ours = our_policy_episodes(suite, checkpoint, "AlohaInsertion-v0", seed=3, episodes=1, horizon=6)
    assert_same_episodes(ours, doc["runs"][0], "AlohaInsertion-v0 act")


#: the slow test's episode length
STEPS = int(os.environ.get("MOLMO_ALOHA_PARITY_STEPS", "50"))


@pytest.mark.slow
@pytest.mark.timeout(4 * 3600)
@pytest.mark.parametrize("task", list(aloha.TASKS.values()))
def test_twenty_episodes_match_lerobot_eval(venv, suite, task):
    """Per task five episodes of each policy (with the other task's: 20), ``MOLMO_ALOHA_PARITY_STEPS`` (default 50)
    steps each (an eighth of LeRobot's 400: its env draws three 480 × 640 cameras a step, ~0.3 s of CPU here)."""
    rows = []
    for policy in POLICIES:
        theirs = reference(venv, task, STEPS, env={"policy": policy, "seed": 0, "episodes": 5})["env"]
        assert_same_env_episodes(our_env_episodes(suite, task, policy, 0, 5, STEPS), theirs, f"{task} {policy}")
        rows += [(task, policy, k, t["success"], t["steps"], max(t["rewards"])) for k, t in enumerate(theirs)]
    print("\ntask policy seed success steps max_reward")
    for row in rows:
        print(*row)
