"""Durable progress: a killed run resumes with ``resume=true`` and ends as an uninterrupted run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from molmo_lerobot.errors import RunError
from molmo_lerobot.runner.evaluate import run_evaluation

EVAL = [sys.executable, "-m", "molmo_lerobot.cli.eval"]


def _lines(path: Path) -> list[str]:
    return [ln for ln in path.read_text().splitlines() if ln.strip()] if path.exists() else []


def _wait_group_gone(pgid: int, timeout_s: float) -> bool:
    """Whether every process of group ``pgid`` exited within ``timeout_s`` (else they are killed)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.1)
    os.killpg(pgid, signal.SIGKILL)
    return False


def _kill_eval_after(args: list[str], out: Path, n_done: int, timeout_s: float = 240) -> int:
    """Start ``molmo-eval`` in its own process group, SIGKILL it once ``n_done`` episodes are on disk."""
    log = open(out.parent / f"{out.name}.stderr", "w")  # noqa: SIM115 - outlives the killed process
    proc = subprocess.Popen([*EVAL, *args], start_new_session=True, stdout=subprocess.DEVNULL, stderr=log)
    log.close()
    deadline = time.monotonic() + timeout_s
    try:
        while len(_lines(out / "episodes.jsonl")) < n_done:
            if proc.poll() is not None:
                tail = (out.parent / f"{out.name}.stderr").read_text()[-2000:]
                pytest.fail(f"molmo-eval exited with {proc.returncode} before it was killed: {tail}")
            if time.monotonic() > deadline:
                pytest.fail("molmo-eval made no progress")
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)
    return proc.pid


@pytest.mark.slow
def test_sigkilled_run_resumes_to_the_uninterrupted_result(faulty_policy, small_bench, tmp_path, eval_config,
                                                           outcomes):
    markers = faulty_policy.marker_dir
    common = ["policy=faulty", "workers=2", "horizon=6", "policy.act_sleep_s=0.04",
              "+policy.faults={5: raise}", f"policy.marker_dir={markers}", f"benchmark.path={small_bench}",
              "progress=false"]
    ref = run_evaluation(eval_config(small_bench, tmp_path / "ref", *common))

    out = tmp_path / "run"
    pgid = _kill_eval_after([*common, f"output_dir={out}"], out, n_done=3)
    assert _wait_group_gone(pgid, 60), "orphaned workers of the killed run did not exit by themselves"
    done = _lines(out / "episodes.jsonl")
    assert 3 <= len(done) < 8, "the kill landed mid-run"
    assert not (out / "results.json").exists(), "a killed run must not look complete"
    with pytest.raises(RunError, match="resume=true"):
        run_evaluation(eval_config(small_bench, out, *common))

    finished_before = {json.loads(ln)["episode_index"] for ln in done if ln.endswith("}")}
    resumed = run_evaluation(eval_config(small_bench, out, *common, "resume=true"))
    assert outcomes(out) == outcomes(tmp_path / "ref")
    assert [r.episode_index for r in resumed.episodes] == list(range(8))
    assert len(_lines(out / "episodes.jsonl")) == 8, "one line per episode after resume"
    for key in ("success_rate", "n_episodes", "n_errors", "benchmark", "per_task", "errors"):
        assert resumed.summary[key] == ref.summary[key], key
    for i in finished_before:  # finished episodes are not rerun
        assert len((markers / f"pids-{i}").read_text().split()) == 2  # once for ref, once for the killed run


def test_torn_last_line_is_rerun_and_finished_episodes_are_kept(faulty_policy, small_bench, tmp_path, eval_config,
                                                                outcomes, fork_servers):
    markers = faulty_policy.marker_dir
    common = ["policy=faulty", "workers=1", "horizon=2", "limit=3", f"policy.marker_dir={markers}"]
    out = tmp_path / "run"
    run_evaluation(eval_config(small_bench, out, *common), fork_servers)
    complete = outcomes(out)
    lines = _lines(out / "episodes.jsonl")
    (out / "episodes.jsonl").write_text(lines[0] + "\n" + lines[1][: len(lines[1]) // 2])
    (out / "results.json").unlink()

    run_evaluation(eval_config(small_bench, out, *common, "resume=true"), fork_servers)
    assert outcomes(out) == complete
    first = json.loads(lines[0])["episode_index"]
    runs = {i: len((markers / f"pids-{i}").read_text().split()) for i in range(3)}
    assert runs == {i: 1 if i == first else 2 for i in range(3)}


def test_resume_refuses_a_different_run(faulty_policy, small_bench, tmp_path, eval_config, monkeypatch, fork_servers):
    out = tmp_path / "run"
    common = ["policy=faulty", "workers=1", "horizon=2", "limit=1", f"policy.marker_dir={faulty_policy.marker_dir}"]
    first = run_evaluation(eval_config(small_bench, out, *common), fork_servers)
    with pytest.raises(RunError, match="already holds a run"):
        run_evaluation(eval_config(small_bench, out, *common), fork_servers)
    with pytest.raises(RunError, match="seed differs"):
        run_evaluation(eval_config(small_bench, out, *common, "resume=true", "seed=1"), fork_servers)
    with pytest.raises(RunError, match=r"timing.policy_dt_ms differs from the run's \(66.0 in run.json, 100 given\)"):
        run_evaluation(eval_config(small_bench, out, *common, "resume=true", "timing.policy_dt_ms=100"), fork_servers)
    # issue 36: an environment override of the look (here shadows off) is part of the run, never silent
    assert first.summary["render_profile"]["name"] == "v2" and first.summary["render_profile"]["overrides"] == {}
    monkeypatch.setenv("MOLMO_SCENE_SHADOWS", "0")
    with pytest.raises(RunError, match="render_profile differs") as info:
        run_evaluation(eval_config(small_bench, out, *common, "resume=true"), fork_servers)
    assert "\n" not in str(info.value) and "MOLMO_SCENE_SHADOWS" in str(info.value)
    assert (out / "results.json").exists(), "a refused resume leaves the finished run alone"


@pytest.mark.slow
def test_recorded_run_killed_and_resumed_gives_one_consistent_dataset(small_bench, tmp_path, eval_config, outcomes):
    """record=true: after SIGKILL + resume the dataset holds each episode exactly once, matching the results."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    common = ["policy=scripted", "workers=2", "horizon=15", "record=true", f"benchmark.path={small_bench}",
              "progress=false"]
    out = tmp_path / "run"
    pgid = _kill_eval_after([*common, f"output_dir={out}"], out, n_done=3)
    assert _wait_group_gone(pgid, 120), "orphaned workers of the killed run did not exit by themselves"
    assert not (out / "dataset").exists() and not (out / "results.json").exists()
    res = run_evaluation(eval_config(small_bench, out, *common, "resume=true"))
    recorded = [r for r in res.episodes if r.error is None]
    ds = LeRobotDataset("local/recorded", root=out / "dataset", video_backend="pyav")
    assert ds.meta.total_episodes == len(recorded) == 8
    assert ds.meta.total_frames == sum(r.steps for r in recorded)
    evals = [json.loads(ln) for ln in _lines(out / "dataset" / "meta" / "eval" / "episodes.jsonl")]
    assert sorted(e["benchmark_episode_index"] for e in evals) == list(range(8))
    by_index = {o["episode_index"]: o for o in outcomes(out)}
    for e in evals:
        assert e["success"] == by_index[e["benchmark_episode_index"]]["success"]
