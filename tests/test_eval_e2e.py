"""End to end through ``molmo-eval``: outputs match the contract, outcomes do not depend on workers."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from molmo_lerobot.config import compose
from molmo_lerobot.runner.evaluate import run_evaluation

EPISODE_KEYS = {"episode_index", "house_index", "task_cls", "success", "success_once", "steps", "seed", "error"}
RESULT_KEYS = {"success_rate", "success_once_rate", "n_episodes", "n_success", "n_errors", "ci95", "per_task",
               "benchmark", "policy", "thresholds", "versions", "seed"}


def _episodes(path):
    return [json.loads(line) for line in (path / "episodes.jsonl").read_text().splitlines()]


def _outcomes(rows):
    return [(r["episode_index"], r["success"], r["success_once"], r["steps"], r["seed"], r["error"]) for r in rows]


@pytest.fixture(scope="module")
def two_worker_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("w2") / "run"
    env = {**os.environ, "MUJOCO_GL": "egl"}
    proc = subprocess.run(
        [sys.executable, "-m", "molmo_lerobot.cli.eval", "policy=scripted", "benchmark=pick_v1", "workers=2",
         "limit=2", f"output_dir={out}", "progress=false"],
        capture_output=True, text=True, env=env, timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out, proc.stdout


def test_contract_outputs(two_worker_run):
    out, stdout = two_worker_run
    results = json.loads((out / "results.json").read_text())
    assert set(results) >= RESULT_KEYS
    assert results["n_episodes"] == 2 and results["n_errors"] == 0
    assert results["benchmark"]["name"] == "pick_v1" and len(results["benchmark"]["sha256"]) == 64
    assert results["benchmark"]["n_episodes"] >= 50
    assert results["policy"]["name"] == "scripted"
    lo, hi = results["ci95"]
    assert 0.0 <= lo <= results["success_rate"] <= hi <= 1.0
    assert results["thresholds"]["pick"]["succ_pos_threshold"] == pytest.approx(0.01)
    assert results["thresholds"]["pick"]["horizon_steps"] == [303]
    assert {"mujoco", "lerobot", "python"} <= set(results["versions"])
    rows = _episodes(out)
    assert [r["episode_index"] for r in rows] == [0, 1]
    assert all(set(r) >= EPISODE_KEYS for r in rows)
    assert all(r["steps"] == 303 for r in rows)
    assert "pick_v1 · scripted: success" in stdout


def test_report_has_a_thumbnail_and_first_success_per_episode_without_recording(two_worker_run):
    """record=false: the worker-side glance recorder still saves first | last exterior frame per episode."""
    out, _ = two_worker_run
    rows = _episodes(out)
    page = (out / "report.html").read_text()
    for r in rows:
        assert r["extra"]["thumbnail"] == f"thumbnails/{r['episode_index']:06d}.jpg"
        assert (out / r["extra"]["thumbnail"]).stat().st_size > 1000
        assert f'<img src="{r["extra"]["thumbnail"]}"' in page
        assert r["extra"]["object_category"]
        assert (r["extra"]["first_success_step"] is not None) == r["success_once"]
    assert not (out / "dataset").exists()


def test_workers_do_not_change_outcomes(two_worker_run, tmp_path):
    """Nor does how workers start: two forked from the preloaded fork server (the default) against
    one spawned; each reports where its start-up went."""
    out2, _ = two_worker_run
    res1 = run_evaluation(compose(["policy=scripted", "workers=1", "limit=2", f"output_dir={tmp_path / 'w1'}",
                                   "progress=false", "executor.start_method=spawn"]))
    assert _outcomes(_episodes(tmp_path / "w1")) == _outcomes(_episodes(out2))
    assert [r.success for r in res1.episodes] == [r["success"] for r in _episodes(out2)]
    phases = {"launch_s", "imports_s", "context_s", "policy_s", "first_scene_s", "renderer_s", "ready_s", "total_s"}
    forked = json.loads((out2 / "results.json").read_text())["startup"]
    assert set(forked["workers"]) == {"w0g0", "w1g0"} and set(forked["median"]) >= phases
    spawned = res1.summary["startup"]["workers"]["w0g0"]
    assert spawned["imports_s"] > 10 * forked["workers"]["w1g0"]["imports_s"]  # the fork server had them


def test_seed_changes_episode_seeds_only_where_asked(two_worker_run, tmp_path, fork_servers):
    out2, _ = two_worker_run
    res = run_evaluation(compose(["policy=random", "workers=1", "limit=2", "seed=1", "horizon=5",
                                  f"output_dir={tmp_path / 's1'}", "progress=false"]), fork_servers)
    seeds0 = [r["seed"] for r in _episodes(out2)[:2]]
    assert [r.seed for r in res.episodes] != seeds0
    assert res.summary["seed"] == 1


@pytest.mark.slow
def test_scripted_full_pick_v1(tmp_path):
    res = run_evaluation(compose(["policy=scripted", "workers=2", f"output_dir={tmp_path}", "progress=false"]))
    assert res.summary["n_episodes"] >= 50 and res.summary["n_errors"] == 0
    assert res.summary["success_rate"] >= 0.80


@pytest.mark.slow
def test_random_floor(tmp_path):
    res = run_evaluation(compose(["policy=random", "workers=2", "limit=20", f"output_dir={tmp_path}",
                                  "progress=false"]))
    assert res.summary["n_episodes"] == 20 and res.summary["n_errors"] == 0
    assert res.summary["success_rate"] <= 0.10


@pytest.mark.slow
def test_a_failed_hub_push_exits_non_zero_and_keeps_every_local_file(hub_standin, tmp_path):
    """The Hub refuses the commit: molmo-eval says so, exits 1, and every output is still written. ``slow``
    (a whole molmo-eval process): the default run has its parts, the refused commit recorded with every local
    file kept (tests/export/test_export_hub.py) and its exit status 1 (``test_the_exit_status_of_a_finished_run``)."""
    hub_standin.fail_commits = 503
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "molmo_lerobot.cli.eval", "policy=scripted", "benchmark=pick_v1", "workers=1",
         "limit=1", "horizon=4", "record=true", "push=true", "hub.repo_id=molmo-test/failing-push",
         f"output_dir={out}", "progress=false"],
        capture_output=True, text=True, env={**os.environ, "MUJOCO_GL": "egl"}, timeout=600,
    )
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert "push to the Hub as molmo-test/failing-push failed" in proc.stderr
    assert f"every local file is kept in {out}" in proc.stderr
    results = json.loads((out / "results.json").read_text())
    assert results["push"]["ok"] is False and "503" in results["push"]["error"]
    assert results["n_episodes"] == 1
    for name in ("episodes.jsonl", "run.json", "report.html", "dataset/meta/info.json", "dataset/results.json",
                 "dataset/meta/eval/episodes.jsonl", "dataset/README.md"):
        assert (out / name).is_file(), name
    assert ("POST", "/api/datasets/molmo-test/failing-push/commit/main") in hub_standin.requests
