"""LeRobot policies scored as ``lerobot-eval`` scores them: the same checkpoint through LeRobot's own evaluation and
through ``molmo-eval policy=lerobot`` at its defaults, on the same episodes, must give the same action at every step
and the same outcomes.

Checkpoints (``tiny_policies.py``, random init, saved with the suite's features): a tiny ACT at the env's image size,
the same ACT declared at another size (``lerobot-eval`` hands it the env's frames and its pre-processor decides; we
must not resize), and a tiny diffusion policy (an observation history and DDPM noise from torch's RNG, which both
sides seed per episode: ``lerobot_policy_reference.py``). LeRobot's side is ``lerobot_policy_reference.py``
(``eval_main``'s set-up, ``eval_policy``); ours what a ``molmo-eval`` worker plays: the planned episodes as plans, a
``SuiteSession`` each, the run's policy (``make_policy`` of the composed config) and our rollout loop. PushT runs in
this process; LIBERO's side is in ``test_libero_parity.py`` (its LIBERO process). ``-m slow`` plays PushT's full
300-step episodes, and a real ``molmo-eval … record=true`` run per checkpoint whose dataset holds LeRobot's actions.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lerobot_policy_reference import lerobot_eval_episodes, make_lerobot_env
from policy_parity import assert_same_episodes, molmo_policy, needs_diffusers, play_session
from tiny_policies import save_act, save_diffusion

from molmo_lerobot.benchmark_kinds import run_kind
from molmo_lerobot.config import compose
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.suites import pusht
from molmo_lerobot.suites.benchmark import suite_plan

pytest.importorskip("gym_pusht")

#: (name, saver, declared image size): at the env's size and at another one
PUSHT_CHECKPOINTS = [pytest.param("act", save_act, pusht.IMAGE_SIZE, id="act"),
                     pytest.param("act_at_64", save_act, 64, id="act_at_64"),
                     pytest.param("diffusion", save_diffusion, pusht.IMAGE_SIZE, id="diffusion", marks=needs_diffusers)]


def molmo_eval_episodes(checkpoint: Path, overrides: list[str]) -> list[dict[str, Any]]:
    """``molmo-eval policy=lerobot policy.path=<checkpoint> <overrides>``'s episodes as a worker plays them."""
    config = RunConfig.of(compose(["policy=random", *overrides]))
    bench = run_kind(Plugins(), config).benchmark_of(config)
    policy, sessions = molmo_policy(checkpoint), run_kind(Plugins(), config).sessions_of(config)
    try:
        plans = [suite_plan(i, bench.suite, episode, True) for i, episode in enumerate(bench.episodes)]
        return [play_session(sessions.open(plan, policy, end_on_success=True), policy, pusht.MOVE_GROUP)
                for plan in plans]
    finally:
        sessions.close()
        policy.close()


def pusht_parity(checkpoint: Path, seed: int, episodes: int, horizon: int) -> list[dict[str, Any]]:
    from lerobot.envs.configs import PushtEnv

    cfg = PushtEnv(episode_length=horizon)
    env = make_lerobot_env(cfg)
    try:
        theirs = lerobot_eval_episodes(cfg, env, checkpoint, seed, episodes)
    finally:
        env.close()
    ours = molmo_eval_episodes(checkpoint, ["benchmark=pusht", f"seed={seed}", f"horizon={horizon}",
                                f"benchmark.episodes_per_task={episodes}"])
    assert_same_episodes(ours, theirs, f"pusht {checkpoint.name}")
    return theirs


@pytest.mark.parametrize(("name", "save", "size"), PUSHT_CHECKPOINTS)
def test_pusht_actions_are_lerobot_evals(tmp_path, name, save, size):
    pusht_parity(save(tmp_path / name, "pusht", size), seed=1000, episodes=2, horizon=8)


@pytest.mark.slow
@pytest.mark.parametrize(("name", "save", "size"), PUSHT_CHECKPOINTS)
def test_pusht_full_episodes_actions_are_lerobot_evals(tmp_path, name, save, size):
    rows = pusht_parity(save(tmp_path / name, "pusht", size), seed=0, episodes=3, horizon=pusht.MAX_STEPS)
    print(f"\n{name}: " + ", ".join(f"seed {r['seed']}: {r['steps']} steps, success {r['success']}" for r in rows))


def recorded_episodes(run_dir: Path) -> list[dict[str, Any]]:
    """A ``record=true`` PushT run's episodes from its directory: per benchmark episode its success, seed and steps
    (``episodes.jsonl``) and its recorded actions (``dataset/``, float32 as the policy gave them)."""
    import pandas as pd

    from molmo_lerobot.results import read_run

    results = sorted(read_run(run_dir, finished=False).episodes, key=lambda e: e.episode_index)
    frames = pd.concat(pd.read_parquet(p) for p in sorted((run_dir / "dataset" / "data").rglob("*.parquet")))
    evals = (run_dir / "dataset" / "meta" / "eval" / "episodes.jsonl").read_text().splitlines()
    stored = {e["benchmark_episode_index"]: e["episode_index"] for e in map(json.loads, evals)}
    out = []
    for result in results:
        rows = frames[frames["episode_index"] == stored[result.episode_index]].sort_values("frame_index")
        out.append({"success": result.success, "seed": result.seed, "steps": result.steps,
                    "actions": [np.asarray(a, dtype=np.float32).tolist() for a in rows["action"]]})
    return out


@pytest.mark.slow
@pytest.mark.parametrize(("name", "save", "size"), PUSHT_CHECKPOINTS)
def test_molmo_eval_runs_record_lerobot_evals_actions(tmp_path, name, save, size):
    """``molmo-eval policy=lerobot policy.path=… benchmark=pusht record=true workers=2 worker_threads=null``: its
    workers' episodes and the actions its dataset holds are LeRobot's. ``worker_threads=null`` leaves torch its
    default thread count, as ``lerobot-eval`` does: CPU kernels round differently with another count (our default of
    one thread per worker moves these actions by ~1e-7)."""
    from lerobot.envs.configs import PushtEnv

    from molmo_lerobot.runner.evaluate import run_evaluation

    checkpoint, episodes, horizon = save(tmp_path / name, "pusht", size), 4, 40
    run_evaluation(compose(["policy=lerobot", f"policy.path={checkpoint}", "policy.device=cpu", "benchmark=pusht",
                            f"benchmark.episodes_per_task={episodes}", f"horizon={horizon}", "record=true",
                            "workers=2", "worker_threads=null", "progress=false", f"output_dir={tmp_path / 'run'}"]))
    cfg = PushtEnv(episode_length=horizon)
    env = make_lerobot_env(cfg)
    try:
        theirs = lerobot_eval_episodes(cfg, env, checkpoint, 0, episodes)
    finally:
        env.close()
    assert_same_episodes(recorded_episodes(tmp_path / "run"), theirs, f"molmo-eval pusht {name}")
