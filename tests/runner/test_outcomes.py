"""Outcomes stand: an output that cannot be written never changes an episode's outcome, and an
infrastructure failure (full disk, dead worker, lost policy server) is told apart from an episode
error and run again by ``resume=true``, which then gives the uninterrupted result."""

from __future__ import annotations

import json

import pytest

from molmo_lerobot.runner.evaluate import run_evaluation


def _records(run_dir):
    rows = [json.loads(line) for line in (run_dir / "episodes.jsonl").read_text().splitlines() if line.strip()]
    return {r["episode_index"]: r for r in rows}


def test_output_and_infrastructure_failures_never_rewrite_outcomes_and_resume_repairs_them(
        faulty_policy, small_bench, tmp_path, eval_config, outcomes, traces, fork_servers):
    """On a broken machine: ``thumbnails`` is a file (every thumbnail write fails after its rollout
    finished), a recorder's disk is full, the policy hits a full disk in episode 0 and the worker
    of episode 2 dies on every attempt; episode 3 is a real episode error.

    Episodes 1 and 2's outputs fail but they keep their outcome (``output_errors``); 0 and 2 are
    infrastructure errors, 3 an episode error. Once the machine is repaired, ``resume=true`` runs
    0, 1 and 2 again (not 3) and the run equals the uninterrupted one: outcomes, traces, thumbnails.
    """
    markers, trace_dir = faulty_policy.marker_dir, tmp_path / "traces"
    faults = "+policy.faults={0: disk_full_until_fixed, 2: sigkill_until_fixed, 3: raise}"
    common = ["policy=faulty", "workers=1", "horizon=2", faults, f"policy.marker_dir={markers}"]
    (markers / "fixed").touch()
    run_evaluation(eval_config(small_bench, tmp_path / "ref", *common, "limit=4",
                               f"+trace_dir={tmp_path / 'ref-traces'}"), fork_servers)
    for p in [markers / "fixed", *markers.glob("pids-*")]:
        p.unlink()

    out = tmp_path / "run"
    run_evaluation(eval_config(small_bench, out, *common, "limit=1", f"+trace_dir={trace_dir}"), fork_servers)
    (out / "thumbnails").mkdir(exist_ok=True)
    (out / "thumbnails").rename(tmp_path / "thumbnails")
    (out / "thumbnails").write_text("in the way")
    trace_dir.mkdir(exist_ok=True)
    (trace_dir / "disk-full").touch()
    res = run_evaluation(eval_config(small_bench, out, *common, "limit=4", f"+trace_dir={trace_dir}", "resume=true"),
                         fork_servers)
    by = {r.episode_index: r for r in res.episodes}
    assert by[0].error_kind == "infrastructure" and "No space left on device" in by[0].error
    assert by[2].error_kind == "infrastructure" and "worker process died" in by[2].error
    assert by[3].error_kind == "episode" and by[3].error.startswith("RuntimeError: faulty policy")
    ref = {o["episode_index"]: o for o in outcomes(tmp_path / "ref")}
    assert outcomes(out)[1] == ref[1], "an output failure changed an outcome"
    failed = {e.split(":")[0]: e for e in by[1].output_errors}
    assert sorted(failed) == ["GlanceRecorder", "TraceRecorder"] and "thumbnail" not in by[1].extra
    assert "No space left on device" in failed["TraceRecorder"]
    assert [e["error_kind"] for e in res.summary["errors"]] == ["infrastructure", "infrastructure", "episode"]
    assert [e["episode_index"] for e in res.summary["output_errors"]] == [1]
    assert _records(out)[1]["output_errors"] == by[1].output_errors

    (markers / "fixed").touch()
    (trace_dir / "disk-full").unlink()
    (out / "thumbnails").unlink()
    (tmp_path / "thumbnails").rename(out / "thumbnails")
    resumed = run_evaluation(eval_config(small_bench, out, *common, "limit=4", f"+trace_dir={trace_dir}",
                                         "resume=true"), fork_servers)
    assert outcomes(out) == outcomes(tmp_path / "ref")
    assert resumed.summary["n_errors"] == 1 and resumed.summary["output_errors"] == []
    assert traces(trace_dir) == traces(tmp_path / "ref-traces")
    assert sorted(p.name for p in (out / "thumbnails").iterdir()) == [f"{i:06d}.jpg" for i in range(3)]
    assert not list(out.rglob("*.tmp"))
    runs = {i: len((markers / f"pids-{i}").read_text().split()) for i in range(4)}
    # 0 (a full disk, an infrastructure failure) and 2 (a dead worker) are retried once in each broken run
    assert runs == {0: 5, 1: 2, 2: 3, 3: 1}, "resume reran exactly the infrastructure and output failures"

    (trace_dir / "trace-1").unlink()  # a recorder's output lost after the run (RecorderFactory.missing)
    run_evaluation(eval_config(small_bench, out, *common, "limit=4", f"+trace_dir={trace_dir}", "resume=true"),
                   fork_servers)
    assert traces(trace_dir) == traces(tmp_path / "ref-traces") and outcomes(out) == outcomes(tmp_path / "ref")
    assert len((markers / "pids-1").read_text().split()) == 3 and len((markers / "pids-0").read_text().split()) == 5


@pytest.mark.slow
def test_a_recorded_run_killed_before_its_shards_were_finished_records_them_on_resume(
        faulty_policy, small_bench, tmp_path, eval_config):
    """``kill -9`` of molmo-eval and its workers after every result was written but before one
    worker finished its dataset shard (no marker: torn) and before the merge: the resume runs
    that shard's episodes again, so the dataset holds every episode the results hold."""
    from molmo_lerobot.export.merge import read_eval_records
    from molmo_lerobot.export.shards import MARKER, list_shards

    markers = faulty_policy.marker_dir
    cfg = ["policy=faulty", "workers=2", "horizon=3", "limit=4", "record=true", f"policy.marker_dir={markers}"]
    out = tmp_path / "run"

    def killed(*args, **kwargs):
        raise KeyboardInterrupt  # stands for the SIGKILL of molmo-eval before its merge

    with pytest.MonkeyPatch.context() as mp, pytest.raises(KeyboardInterrupt):
        mp.setattr("molmo_lerobot.export.merge.merge_shards", killed)
        run_evaluation(eval_config(small_bench, out, *cfg))
    shards = list_shards(out)
    assert len(shards) == 2 and len(_records(out)) == 4
    torn = shards[-1]
    (torn.root / MARKER).unlink()  # its worker was killed before it finished the shard
    lost = sorted(e["episode_index"] for e in torn.episodes)
    assert lost

    res = run_evaluation(eval_config(small_bench, out, *cfg, "resume=true"))
    assert res.summary["n_errors"] == 0
    records = read_eval_records(out / "dataset")
    assert sorted(r["benchmark_episode_index"] for r in records if r["episode_index"] is not None) == [0, 1, 2, 3]
    runs = {i: len((markers / f"pids-{i}").read_text().split()) for i in range(4)}
    assert runs == {i: 2 if i in lost else 1 for i in range(4)}, "resume ran exactly the lost episodes again"
