"""Honest bookkeeping of a run: every attempted episode belongs to its task, a run where nothing
simulated has no score, resume never drops episodes, broken outputs and diverging physics are
one-line errors."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from eval_runs import evaluate, refusal
from molmo_lerobot.cli.eval import exit_status
from molmo_lerobot.errors import RunError
from molmo_lerobot.results import summary_lines
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.runner.plan import horizon_with_source

PICK_CLS = "molmo_lerobot.tasks.pick.PickTask"


def _rows(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / "episodes.jsonl").read_text().splitlines() if x.strip()]


def _bench(small_bench: Path, tmp_path: Path, edit, name="edited") -> Path:
    """A copy of ``small_bench`` with ``edit(episodes)`` applied."""
    episodes = json.loads((small_bench / "benchmark.json").read_text())
    edit(episodes)
    d = tmp_path / name
    d.mkdir()
    (d / "benchmark.json").write_text(json.dumps(episodes))
    return d


def _common(faulty_policy, *more):
    return ["policy=faulty", "workers=1", "horizon=2", f"policy.marker_dir={faulty_policy.marker_dir}", *more]


def test_errored_and_invalid_episodes_count_in_their_task(faulty_policy, small_bench, tmp_path, eval_config,
                                                          fork_servers):
    """Issue 11.2: pick showed 4/6 (errors filed under their task_cls) where the truth was 4/8."""
    def edit(eps):
        eps[3]["cameras"][0]["fov"] = 200  # invalid: fails before any worker sees it

    bench = _bench(small_bench, tmp_path, edit)
    out = tmp_path / "run"
    res = run_evaluation(eval_config(bench, out, *_common(faulty_policy, "limit=5",
                                                          "+policy.faults={1: raise, 4: hang}", "episode_timeout_s=8")),
                         fork_servers)
    assert list(res.summary["per_task"]) == ["pick"]
    pick = res.summary["per_task"]["pick"]
    assert (pick["n_episodes"], pick["n_errors"], pick["n_valid"]) == (5, 3, 2)
    for row in _rows(out):
        assert row["task_type"] == "pick" and row["prompt"] and row["horizon"] == 2, row
        assert row["horizon_source"] == "cli"
    errors = {r["episode_index"]: r["error"] for r in _rows(out) if r["error"]}
    assert set(errors) == {1, 3, 4} and errors[3].startswith("invalid episode") and "timed out" in errors[4]


def test_horizon_sources():
    class Task:
        task_horizon_sec = None

    timed = Task()
    timed.task_horizon_sec = 0.66
    assert horizon_with_source(7, timed, 15.0, 66.0, 2.0) == (7, "cli")
    assert horizon_with_source(None, timed, 15.0, 66.0, 0.132) == (2, "task_horizons")
    assert horizon_with_source(None, timed, 15.0, 66.0) == (10, "task_horizon_sec")
    assert horizon_with_source(None, Task(), 1.32, 66.0) == (20, "default")


def test_horizon_source_is_recorded_per_episode(faulty_policy, small_bench, tmp_path, eval_config, fork_servers):
    def edit(eps):
        eps[0]["task"]["task_horizon_sec"] = 0.132
        del eps[1]["task"]["task_horizon_sec"]  # pick's default, 20 s

    bench = _bench(small_bench, tmp_path, edit)
    out = tmp_path / "run"
    run_evaluation(eval_config(bench, out, "policy=faulty", "workers=1", "limit=2", "timing.policy_dt_ms=330",
                               "timing.ctrl_dt_ms=10", "timing.sim_dt_ms=10",
                               f"policy.marker_dir={faulty_policy.marker_dir}"), fork_servers)
    rows = _rows(out)
    assert [(r["horizon"], r["horizon_source"]) for r in rows] == [(1, "task_horizon_sec"), (61, "default")]


def test_a_run_where_every_episode_errored_has_no_score(faulty_policy, small_bench, tmp_path, fork_servers):
    out = tmp_path / "run"
    res = evaluate(f"benchmark.path={small_bench}", f"output_dir={out}", "progress=false",
                   *_common(faulty_policy, "limit=2", "+policy.faults={0: raise, 1: raise}"), fork_servers=fork_servers)
    assert exit_status(res.summary) == 1
    text = "\n".join(summary_lines(res.run_summary))
    assert text.startswith("no episode ran: 2 of 2 episodes errored") and "success 0.000" not in text
    summary = json.loads((out / "results.json").read_text())
    assert summary["success_rate"] is None and summary["ci95"] is None
    assert (summary["n_episodes"], summary["n_errors"], summary["n_valid"], summary["n_success"]) == (2, 2, 0, 0)
    assert summary["per_task"]["pick"]["success_rate"] is None
    assert (out / "report.html").exists()


def test_a_run_with_errors_leads_with_them(faulty_policy, small_bench, tmp_path, fork_servers):
    out = tmp_path / "run"
    res = evaluate(f"benchmark.path={small_bench}", f"output_dir={out}", "progress=false",
                   *_common(faulty_policy, "limit=3", "+policy.faults={1: raise}"), fork_servers=fork_servers)
    assert exit_status(res.summary) == 0
    first = summary_lines(res.run_summary)[0]
    assert first.startswith("1 of 3 episodes errored · pick_small · faulty: success 0.000")
    summary = json.loads((out / "results.json").read_text())
    assert summary["n_valid"] == 2 and summary["success_rate"] == 0.0


def test_resume_with_a_smaller_limit_keeps_every_episode(faulty_policy, small_bench, tmp_path, eval_config,
                                                         fork_servers):
    """Issue 11.3: episodes.jsonl went from 12 lines to 4, silently."""
    out = tmp_path / "run"
    run_evaluation(eval_config(small_bench, out, *_common(faulty_policy, "limit=4")), fork_servers)
    before = (out / "episodes.jsonl").read_text()
    with pytest.raises(RunError, match=r"with limit=2: it was started with limit=4 \(4 episodes recorded\).*never "
                                       r"drops recorded episodes; use limit=4 or larger"):
        run_evaluation(eval_config(small_bench, out, *_common(faulty_policy, "limit=2", "resume=true")), fork_servers)
    assert (out / "episodes.jsonl").read_text() == before and (out / "results.json").exists()
    res = run_evaluation(eval_config(small_bench, out, *_common(faulty_policy, "limit=6", "resume=true")), fork_servers)
    assert [r["episode_index"] for r in _rows(out)] == list(range(6)) and res.summary["n_episodes"] == 6
    assert json.loads((out / "run.json").read_text())["limit"] == 6
    with pytest.raises(RunError, match="limit=5"):
        run_evaluation(eval_config(small_bench, out, *_common(faulty_policy, "limit=5", "resume=true")), fork_servers)
    # keeps limit=6
    res = run_evaluation(eval_config(small_bench, out, *_common(faulty_policy, "resume=true")), fork_servers)
    assert res.summary["n_episodes"] == 6 and len(_rows(out)) == 6
    with pytest.raises(RunError, match=r"with limit=3: it was started with limit=6 \(6 episodes recorded\).*use "
                                       r"limit=6 or larger \(or leave limit out to keep 6\)"):
        run_evaluation(eval_config(small_bench, out, *_common(faulty_policy, "limit=3", "resume=true")), fork_servers)
    assert len(_rows(out)) == 6


def test_resume_names_a_corrupt_record(faulty_policy, small_bench, tmp_path, eval_config, fork_servers):
    out = tmp_path / "run"
    common = _common(faulty_policy, "limit=3")
    run_evaluation(eval_config(small_bench, out, *common), fork_servers)
    lines = (out / "episodes.jsonl").read_text().splitlines()
    for bad in ('{"episode_index": 1, "success": "yes"}', "not json at all", "[" * 100_000 + "]" * 100_000):
        (out / "episodes.jsonl").write_text("\n".join([lines[0], bad, lines[2]]) + "\n")
        with pytest.raises(RunError, match=r"episodes.jsonl:2: corrupt episode record .*delete that line"):
            run_evaluation(eval_config(small_bench, out, *common, "resume=true"), fork_servers)


def test_output_dir_that_cannot_be_written_is_one_line(tmp_path):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    for out, needle in ((a_file, f"output_dir {a_file} is a file, not a directory"),
                        (a_file / "sub", f"cannot write output_dir {a_file / 'sub'}: Not a directory"),
                        (Path("/sys/molmo-out"), "cannot write output_dir /sys/molmo-out: Operation not permitted")):
        [line] = refusal("limit=1", "horizon=1", f"output_dir={out}")
        assert needle in line, line
    assert a_file.read_text() == "x"


def test_deeply_nested_benchmark_is_one_line_in_molmo_eval(small_bench, tmp_path):
    d = tmp_path / "deep"
    d.mkdir()
    (d / "benchmark.json").write_text("[" * 100_000 + "]" * 100_000)
    [line] = refusal(f"benchmark.path={d}", f"output_dir={tmp_path / 'out'}")
    assert "JSON nested deeper than" in line and not (tmp_path / "out").exists()


def _limit_file_size(nbytes: int):
    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))


def test_a_full_disk_mid_run_leaves_episodes_jsonl_valid_for_resume(faulty_policy, small_bench, tmp_path,
                                                                    eval_config, fork_servers):
    """Writes past RLIMIT_FSIZE fail with EFBIG (Python ignores SIGXFSZ) as a full disk fails with ENOSPC."""
    out = tmp_path / "run"
    args = [f"benchmark.path={small_bench}", f"output_dir={out}", "progress=false", *_common(faulty_policy, "limit=8")]
    max_file = 4500  # run.json (~3.7 kB with its options) fits; episodes.jsonl fills up after 7 ~600-byte records
    proc = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.eval", *args], capture_output=True, text=True,
                          timeout=300, preexec_fn=_limit_file_size(max_file),
                          env={**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH", "")})
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "resume=true" in proc.stderr
    assert "molmo-eval: error: cannot write episode" in proc.stderr
    text = (out / "episodes.jsonl").read_text()
    assert text.endswith("\n") and 1 <= len(text.splitlines()) < 8
    assert all(json.loads(line)["task_type"] == "pick" for line in text.splitlines())
    assert not (out / "results.json").exists()
    res = run_evaluation(eval_config(small_bench, out, *_common(faulty_policy, "resume=true")), fork_servers)
    assert res.summary["n_episodes"] == 8 and len(_rows(out)) == 8


def test_diverging_physics_is_an_episode_error(faulty_policy, small_bench, tmp_path, eval_config, fork_servers):
    """Issue 11.13: init_qpos of 1e9 gave "simulation unstable" warnings and a plain failure with error null."""
    def edit(eps):
        eps[0]["robot"]["init_qpos"]["arm"] = [1e9] * 7
        obj = eps[1]["task"]["pickup_obj_name"]
        eps[1]["scene_modifications"]["object_poses"][obj] = [1e308, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]

    bench = _bench(small_bench, tmp_path, edit)
    out = tmp_path / "run"
    res = run_evaluation(eval_config(bench, out, *_common(faulty_policy, "limit=3")), fork_servers)
    errors = [r.error for r in res.episodes]
    assert errors[0].startswith("SimulationDiverged: simulation diverged at step 0") and "mjWARN_BADQACC" in errors[0]
    assert errors[1].startswith("SimulationDiverged: simulation diverged at") and "mjWARN_BADQPOS" in errors[1]
    assert errors[2] is None
    assert res.summary["n_errors"] == 2 and res.summary["n_valid"] == 1


def test_benchmark_names_stay_inside_runs(faulty_policy, small_bench, tmp_path, eval_config, monkeypatch, fork_servers):
    """Issue 11.9: name "../../../../tmp/x" moved the default output dir outside runs/."""
    bench = _bench(small_bench, tmp_path, lambda eps: None)
    (bench / "benchmark_metadata.json").write_text(json.dumps({"name": "../../../../tmp/x"}))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    cfg = eval_config(bench, None, *_common(faulty_policy, "limit=1"))
    cfg.output_dir = None
    res = run_evaluation(cfg, fork_servers)
    assert res.output_dir.resolve().parent == (work / "runs").resolve()
    assert res.output_dir.name.startswith("tmp_x-faulty-")
    assert res.summary["benchmark"]["name"] == "../../../../tmp/x"  # recorded as given
