"""``molmo-eval benchmark=pusht``: LeRobot's PushT episodes through our workers, results and resume.

gym_pusht runs in the worker's own process (no venv of its own); a step costs ~10 ms here, so these runs play
full sets of short episodes.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from eval_runs import interrupted, molmo_eval
from molmo_lerobot.benchmark_kinds import BenchmarkKindError, run_kind
from molmo_lerobot.config import compose
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.random_policy import RandomPolicy
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.suites import pusht
from molmo_lerobot.suites.benchmark import suite_plan

pytest.importorskip("gym_pusht")

ARGS = ["policy=random", "benchmark=pusht", "horizon=30", "progress=false"]


def test_pusht_run_with_two_workers_scores_per_task(tmp_path):
    res = run_evaluation(compose([*ARGS, "workers=2", "limit=4", f"output_dir={tmp_path}"]))
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["n_episodes"] == 4 and doc["n_errors"] == 0 and list(doc["per_task"]) == ["pusht/PushT-v0"]
    lines = sorted((json.loads(line) for line in (tmp_path / "episodes.jsonl").read_text().splitlines()),
                   key=lambda e: e["episode_index"])
    # lerobot-eval's seeding: episode k of a run with seed 0 is reset with seed k
    assert [(e["seed"], e["steps"], e["horizon"], e["error"]) for e in lines] == [(k, 30, 30, None) for k in range(4)]
    assert len({e["extra"]["digest"] for e in lines}) == 4
    assert res.run_summary.n_episodes == 4
    # gym_pusht's rewards, per episode and averaged (lerobot-eval's figures), beside results.json too
    task = doc["per_task"]["pusht/PushT-v0"]
    assert task["avg_max_reward"] == sum(e["extra"]["max_reward"] for e in lines) / 4 and task["instructions"] == [""]
    info = json.loads((tmp_path / "eval_info.json").read_text())
    assert [(t["task_group"], t["task_id"], len(t["metrics"]["max_rewards"])) for t in info["per_task"]] == [
        ("pusht", 0, 4)]
    assert info["overall"]["avg_max_reward"] == doc["avg_max_reward"] and info["overall"]["n_episodes"] == 4
    assert "Per house" not in (tmp_path / "report.html").read_text()  # an env suite's episodes have no house


@pytest.mark.slow
def test_pusht_run_resumes_the_episodes_left(tmp_path):
    run_evaluation(compose([*ARGS, "workers=1", "limit=1", f"output_dir={tmp_path}"]))
    kept = (tmp_path / "episodes.jsonl").read_text().splitlines()
    run_evaluation(compose([*ARGS, "workers=1", "limit=2", "resume=true", f"output_dir={tmp_path}"]))
    lines = (tmp_path / "episodes.jsonl").read_text().splitlines()
    assert lines[:1] == kept and len(lines) == 2 and json.loads(lines[1])["seed"] == 1


def _outcomes(out) -> list[tuple]:
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    return sorted((r["episode_index"], r["seed"], r["steps"], r["success"], r["success_once"], r["error"],
                   r["extra"]["success_any_step"]) for r in rows)


@pytest.mark.parametrize("record", [pytest.param(False), pytest.param(True, marks=pytest.mark.slow)])
def test_an_interrupted_run_resumes_with_the_command_it_prints(tmp_path, record):
    """Ctrl-C mid-run prints ``output_dir=… resume=true``; that command alone finishes the run with its own
    options (none of them the defaults) and ends as the uninterrupted run, its recording too."""
    args = [*ARGS, "benchmark.image_size=64", "seed=3", "workers=1", "limit=6",
            *(["record=true", "video.vcodec=h264"] if record else [])]
    run_evaluation(compose([*args, f"output_dir={tmp_path / 'ref'}"]))
    out = tmp_path / "run"
    command = interrupted(*args, out=out, after=2)
    done = molmo_eval(*command.split())
    assert done.returncode == 0, done.stderr[-2000:]
    assert _outcomes(out) == _outcomes(tmp_path / "ref") and len(_outcomes(out)) == 6
    # an option of the run's benchmark group given with the bare resume command is refused naming it
    # (composed in the run's groups, not Hydra's "no such key" against the default benchmark's)
    changed = molmo_eval(*command.split(), "benchmark.image_size=128")
    assert changed.returncode == 2 and "benchmark.image_size differs from the run's (64 in run.json, 128 given)" \
        in changed.stderr, changed.stderr[-2000:]
    if record:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset

        ds = LeRobotDataset("local/x", root=out / "dataset", video_backend="pyav")
        assert ds.meta.total_episodes == 6 and tuple(ds.meta.features["observation.image"]["shape"][:2]) == (64, 64)


def test_random_policy_draws_targets_across_the_workspace():
    config = RunConfig.of(compose(["policy=random", "benchmark=pusht", "horizon=5"]))
    bench = run_kind(Plugins(), config).benchmark_of(config)
    sessions, policy = run_kind(Plugins(), config).sessions_of(config), RandomPolicy({})
    try:
        session = sessions.open(suite_plan(0, bench.suite, bench.episodes[0], True), policy, end_on_success=False)
        obs = session.observe()
        targets = policy.act(obs)[pusht.MOVE_GROUP]
    finally:
        sessions.close()
    assert obs["images"][pusht.CAMERA].shape == (pusht.IMAGE_SIZE, pusht.IMAGE_SIZE, 3)
    assert targets.shape == (policy.chunk, pusht.ACTION_DIM)
    assert np.all((targets >= 0) & (targets <= 512))
    # a target of the workspace, not a step of `scale` (0.15) from the agent's position
    assert np.abs(targets[0] - obs["qpos"][pusht.MOVE_GROUP]).max() > 1.0


def test_pusht_refuses_libero_options():
    config = RunConfig.of(compose(["policy=random", "benchmark=pusht", "+benchmark.hard_reset=false"]))
    with pytest.raises(BenchmarkKindError, match=r"benchmark.hard_reset: not an option .*: episodes_per_task, image_"):
        run_kind(Plugins(), config).options_of(config)
