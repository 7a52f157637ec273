"""The LIBERO env suite against LeRobot's own LIBERO evaluation (``lerobot-eval --env.type=libero``).

Both sides run in the LIBERO venv (``make .libero-venv``): ours is ``LiberoSuite`` + ``play`` (our own
episode plan, reset, settle, observation conventions and step loop over LIBERO's env); theirs is
``lerobot_libero_reference.py`` (LeRobot's ``make_env``, env processors and ``rollout``). For a seeded random
and a fixed replay policy every episode must agree on success and step count, and bit for bit on each 8-D
state and both camera images the policy saw. The default run plays three short episodes of one task (our hard
reset reuses the task's compiled model and render context; LeRobot's rebuilds them); the ≥50-episode
run across the five suites is ``-m slow`` (``MOLMO_LIBERO_PARITY_HORIZON`` shortens its episodes), and so is the
check that the registry asset tree holds every file LIBERO loads (``molmo_lerobot.suites.libero_assets``).
The LIBERO half of the policy parity (``test_policy_parity.py``): LeRobot checkpoints through ``eval_policy``
(``lerobot_policy_reference.py``) and through ``policy=lerobot`` on a ``SuiteSession``, every action equal.
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
from parity_policies import POLICIES
from policy_parity import assert_same_episodes, molmo_policy, needs_diffusers, play_session
from tiny_policies import save_act, save_diffusion

from molmo_lerobot.policies.base import Policy
from molmo_lerobot.recording import Recorder
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.suites.benchmark import SuiteSession, suite_plan
from molmo_lerobot.suites.libero import MAX_STEPS, LiberoSuite, libero_venv, plan_episodes
from molmo_lerobot.suites.plugin import LIBERO

HERE = Path(__file__).parent
SIZE = 128  # smaller than lerobot-eval's 360² to keep the test cheap; both sides render at it


@pytest.fixture(scope="module")
def venv() -> Path:
    path = libero_venv()
    if not (path / "bin" / "python").exists():
        pytest.skip(f"no LIBERO venv at {path} (build it: make .libero-venv)")
    return path


@pytest.fixture(scope="module")
def suite_env(venv):
    """One LIBERO env process for the default tests (its libero_object task 0 env is built once)."""
    with LiberoSuite(venv, image_size=SIZE) as proc:
        yield proc


def theirs(venv: Path, suite: str, task_id: int, episodes: int, seed: int, horizon: int, policy: str,
           hard_reset: bool = True) -> dict:
    args = {"suite": suite, "task_id": task_id, "episodes": episodes, "seed": seed, "horizon": horizon,
            "policy": policy, "size": SIZE, "hard_reset": hard_reset}
    return _reference(venv, "lerobot_libero_reference.py", args, "{")


def _reference(venv: Path, script: str, args: dict, opener: str) -> Any:
    """The JSON document (its lines start with ``opener``) the LeRobot-side ``script`` prints last, run in
    LIBERO's venv with ``args``."""
    env = {**os.environ, "LIBERO_CONFIG_PATH": str(venv / "libero-config"), "MUJOCO_GL": "egl"}
    proc = subprocess.run([str(venv / "bin" / "python"), str(HERE / script), json.dumps(args)],
                          env=env, capture_output=True, text=True, timeout=3600)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith(opener)]
    assert proc.returncode == 0 and lines, proc.stdout[-2000:] + proc.stderr[-3000:]
    return json.loads(lines[-1])


class Scripted(Policy):
    """``POLICIES[name]``'s action of each step, noting the 8-D state and the camera images it was shown."""

    def __init__(self, name: str) -> None:
        self.act_at = POLICIES[name]

    def reset(self, ctx) -> None:
        self.seed, self.seen = ctx.seed, {"states": [], "images": []}

    def act(self, obs: dict) -> dict:
        self.seen["states"].append([float(v) for v in obs["qpos"]["eef"]])
        self.seen["images"].append({feature: hashlib.sha256(obs["images"][camera].tobytes()).hexdigest()
                                    for camera, feature in LIBERO.cameras.items()})
        return {"eef": self.act_at(self.seed, obs["step"])}


def ours(suite_env: LiberoSuite, suite: str, task_id: int, episodes: int, seed: int, horizon: int,
         policy: str) -> list[dict]:
    """The episodes through molmo-eval's own path: each a ``SuiteSession`` played by the one rollout loop."""
    task = suite_env.tasks(suite)[task_id]
    out = []
    for k, episode in enumerate(plan_episodes(suite, [task], episodes, seed=seed, horizon=horizon)):
        agent = Scripted(policy)
        session = SuiteSession(LIBERO, suite_plan(k, LIBERO, episode, True), suite_env, SIZE, end_on_success=True)
        agent.reset(session.policy_context())
        result = rollout(session, agent, [], policy)
        out.append({"success": result.success, "steps": result.steps, **agent.seen})
    return out


def assert_same(mine: list[dict], reference: list[dict], where: str) -> None:
    assert len(mine) == len(reference)
    for k, (a, b) in enumerate(zip(mine, reference, strict=True)):
        label = f"{where} episode {k}"
        assert (a["success"], a["steps"]) == (b["success"], b["steps"]), label
        assert b["done_at"] == b["steps"], label  # LeRobot's own two counts agree
        assert a["images"][0] == b["images"][0], f"{label}: first camera images differ"
        assert a["states"] == b["states"], f"{label}: 8-D state trajectories differ"
        assert a["images"] == b["images"], f"{label}: camera images differ"


@pytest.fixture(scope="module")
def three_short(venv) -> dict:
    """LeRobot's three episodes of libero_object task 0 (init states 0–2), 10 steps of the seeded random policy."""
    return theirs(venv, "libero_object", 0, 3, 7, 10, "random")


def test_three_short_episodes_match_lerobot_eval(three_short, suite_env):
    """Those three episodes, against LeRobot's default hard reset: the second and third episodes start from our
    reused model and render context."""
    assert three_short["max_steps"] == MAX_STEPS
    mine = ours(suite_env, "libero_object", 0, 3, 7, 10, "random")
    assert_same(mine, three_short["episodes"], "libero_object task 0")


class ChunkedRandom(Policy):
    """The parity test's random policy in chunks of ``CHUNK`` actions, run open loop by the rollout; remembers
    the digests of the images it was shown (at each chunk's first step)."""

    CHUNK = 4

    def reset(self, ctx) -> None:
        self.seed, self.shown = ctx.seed, {}

    def act(self, obs) -> dict:
        step = obs["step"]
        self.shown[step] = {f"observation.images.{k}": hashlib.sha256(v.tobytes()).hexdigest()
                            for k, v in obs["images"].items()}
        return {"eef": np.stack([POLICIES["random"](self.seed, t) for t in range(step, step + self.CHUNK)])}


class States(Recorder):
    """Every step's 8-D state, from the observations the rollout hands recorders (it asks for no images)."""

    wants_images = False

    def start_episode(self, info) -> None:
        self.states: list[list[float]] = []

    def record_step(self, obs, action, reward, success, done) -> None:
        self.states.append([float(v) for v in obs["qpos"]["eef"]])

    def end_episode(self, result) -> None:
        pass


def test_a_chunked_run_draws_a_quarter_of_the_frames_with_lerobot_evals_bits(three_short, suite_env):
    """The same three episodes through molmo-eval's own path (``SuiteSession`` + the rollout loop) with the random
    actions in chunks of 4: LIBERO draws frames only at each chunk's first step, and those images, every step's
    state and the outcomes are LeRobot's, which drew every frame (a frame not drawn leaves the sim untouched)."""
    [task] = suite_env.tasks("libero_object")[:1]
    for k, episode in enumerate(plan_episodes("libero_object", [task], 3, seed=7, horizon=10)):
        session = SuiteSession(LIBERO, suite_plan(k, LIBERO, episode, True), suite_env, SIZE, end_on_success=True)
        policy, states = ChunkedRandom(), States()
        policy.reset(session.policy_context())
        states.start_episode(None)
        result = rollout(session, policy, [states], "chunked")
        reference = three_short["episodes"][k]
        assert (result.success, result.steps) == (reference["success"], reference["steps"]), k
        assert states.states == reference["states"], f"episode {k}: 8-D state trajectories differ"
        assert sorted(policy.shown) == [0, 4, 8]
        assert {t: reference["images"][t] for t in policy.shown} == policy.shown, f"episode {k}: images differ"
        with pytest.raises(RuntimeError, match="played without them"):  # its last step drew no frames
            session.observe(images=True)


#: (suite, task id) pairs of the long run: two tasks of each suite, five episodes each = 50 episodes
LONG = [(s, t) for s in ("libero_spatial", "libero_object", "libero_goal", "libero_10", "libero_90") for t in (0, 1)]


@pytest.mark.slow
@pytest.mark.timeout(8 * 3600)  # ~20 min per task pair at full horizon on a loaded 2-core machine
@pytest.mark.parametrize("hard_reset", [True, False], ids=["hard_reset", "soft_reset"])
def test_fifty_episodes_match_lerobot_eval(venv, hard_reset):
    """Five episodes of two tasks of every suite, random and replay policies alternating, in each of LeRobot's
    reset modes (``--env.hard_reset``): a rebuilt model per episode (its default; ours the cheaper rebuild, one
    server across all tasks) or the task's sim reused (soft reset). The two modes do not agree with each other
    (docs/suites.md); each must agree with LeRobot's."""
    horizon = os.environ.get("MOLMO_LIBERO_PARITY_HORIZON")
    rows = []
    with LiberoSuite(venv, image_size=SIZE, hard_reset=hard_reset) as suite_env:
        for i, (suite, task_id) in enumerate(LONG):
            steps = int(horizon) if horizon else MAX_STEPS[suite]
            policy = ("random", "replay")[i % 2]
            reference = theirs(venv, suite, task_id, 5, 1000 * i, steps, policy, hard_reset)
            mine = ours(suite_env, suite, task_id, 5, 1000 * i, steps, policy)
            rows.append((suite, task_id, policy, [(m["success"], m["steps"]) for m in mine]))
            assert_same(mine, reference["episodes"], f"{suite} task {task_id}")
    print("\n".join(f"{s} task {t} {p}: {o}" for s, t, p, o in rows))


@pytest.mark.slow
@pytest.mark.timeout(3 * 3600)
def test_registry_assets_hold_every_file_libero_loads(venv):
    """LIBERO's ControlEnv builds and compiles every task of the five suites from the registry's asset tree."""
    env = {**os.environ, "LIBERO_CONFIG_PATH": str(venv / "libero-config"), "MUJOCO_GL": "egl"}
    proc = subprocess.run([str(venv / "bin" / "python"), "-m", "molmo_lerobot.suites.libero_assets"], env=env,
                          capture_output=True, text=True, timeout=3600)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    assert proc.returncode == 0 and lines, proc.stderr[-3000:]
    report = json.loads(lines[-1])
    print(report)
    assert report["failed"] == {} and report["files_missing"] == []
    assert report["tasks_built"] == 130


#: the policy-parity checkpoints (``test_policy_parity.py``): name, saver, declared image size (the env's: SIZE)
LIBERO_CHECKPOINTS = [("act", save_act, SIZE), ("act_at_256", save_act, 256), ("diffusion", save_diffusion, SIZE)]


def lerobot_policy_episodes(venv: Path, suite: str, task_id: int, horizon: int, runs: list[dict]) -> list[list[dict]]:
    """``lerobot_policy_reference.py``'s runs (checkpoint, seed, episodes) one after the other on one LIBERO env."""
    args = {"suite": suite, "task_id": task_id, "size": SIZE, "horizon": horizon, "runs": runs}
    return _reference(venv, "lerobot_policy_reference.py", args, "[")


def policy_parity(venv: Path, suite_env: LiberoSuite, checkpoints: list[tuple[str, Path]], suite: str, task_id: int,
                  episodes: int, seed: int, horizon: int) -> list[list[dict]]:
    """Each checkpoint's ``episodes`` in turn (LIBERO's init states advance across them, as on LeRobot's one env)
    through LeRobot's evaluation and through ``policy=lerobot`` on a ``SuiteSession`` and our rollout loop; checks
    they agree (actions bit for bit) and returns LeRobot's."""
    task = suite_env.tasks(suite)[task_id]
    planned = plan_episodes(suite, [task], episodes * len(checkpoints), seed=seed, horizon=horizon)
    runs = [{"checkpoint": str(path), "seed": seed + i * episodes, "episodes": episodes}
            for i, (_, path) in enumerate(checkpoints)]
    theirs = lerobot_policy_episodes(venv, suite, task_id, horizon, runs)
    for i, (name, path) in enumerate(checkpoints):
        policy, ours = molmo_policy(path), []
        for k in range(i * episodes, (i + 1) * episodes):
            session = SuiteSession(LIBERO, suite_plan(k, LIBERO, planned[k], True), suite_env, SIZE,
                                   end_on_success=True)
            policy.reset(session.policy_context())
            ours.append(play_session(session, policy, "eef"))
        policy.close()
        assert_same_episodes(ours, theirs[i], f"{suite} task {task_id} {name}")
    return theirs


@pytest.mark.slow  # the default run keeps it under 10 minutes; make test-all runs it
def test_a_checkpoint_at_another_image_size_acts_as_under_lerobot_eval(venv, suite_env, tmp_path):
    """The tiny ACT declared at 256², ``policy=lerobot`` at its defaults: LeRobot hands it the env's 128² frames (its
    pre-processor decides), so must we; one 6-step episode, every action LeRobot's (the other checkpoints: slow)."""
    name, save, size = LIBERO_CHECKPOINTS[1]
    checkpoint = save(tmp_path / name, "libero", size)
    policy_parity(venv, suite_env, [(name, checkpoint)], "libero_object", 0, episodes=1, seed=3, horizon=6)


@pytest.mark.slow
@pytest.mark.timeout(3 * 3600)
@needs_diffusers
def test_lerobot_checkpoints_act_as_under_lerobot_eval_longer(venv, suite_env, tmp_path):
    """The three checkpoints (ACT at the env's size and at 256², diffusion), two 50-step episodes each, on
    libero_object task 0."""
    checkpoints = [(name, save(tmp_path / name, "libero", size)) for name, save, size in LIBERO_CHECKPOINTS]
    theirs = policy_parity(venv, suite_env, checkpoints, "libero_object", 0, episodes=2, seed=0, horizon=50)
    print("\n" + "\n".join(f"{name}: " + ", ".join(f"seed {e['seed']} {e['steps']} steps success {e['success']}"
                                                    for e in episodes)
                             for (name, _), episodes in zip(checkpoints, theirs, strict=True)))
