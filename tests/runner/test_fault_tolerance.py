"""Crash isolation: SIGKILLed, hung and raising episodes never take other episodes down;
SIGTERM/SIGINT stop a run cleanly; molmo-eval leaves no process behind."""

from __future__ import annotations

import json
import os
import signal
import threading
import time

import pytest

from molmo_lerobot.runner.evaluate import run_evaluation

FAULTS = "+policy.faults={1: sigkill, 2: sigkill_once, 4: hang, 5: raise, 6: nan}"


def _check_faults(res, markers):
    by = {r.episode_index: r for r in res.episodes}
    assert sorted(by) == list(range(8)), "every episode is accounted for"
    assert res.summary["n_episodes"] == 8 and res.summary["n_errors"] == 4
    # killed on every attempt: retried once, then an error naming the death
    assert by[1].attempts == 2 and by[1].steps == 0 and not by[1].success
    assert "died" in by[1].error
    assert len((markers / "pids-1").read_text().split()) == 2
    # killed on the first attempt only: the retry completes normally
    assert by[2].error is None and by[2].attempts == 2 and by[2].steps == 3
    assert (markers / "crashed-2").exists()
    # hung: ended by the watchdog, not retried
    assert "timed out" in by[4].error and by[4].attempts == 1
    # raised / invalid action: a per-episode error, the worker lives on
    assert by[5].error.startswith("RuntimeError: faulty policy: raising in episode 5")
    assert "non-finite" in by[6].error and "'arm'" in by[6].error
    for i in (0, 3, 7):
        assert by[i].error is None and by[i].attempts == 1 and by[i].steps == 3
    assert {e["episode_index"] for e in res.summary["errors"]} == {1, 4, 5, 6}


def test_local_pool_isolates_crashes_hangs_and_errors(faulty_policy, small_bench, tmp_path, eval_config, fork_servers):
    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "workers=2", "horizon=3",
                      "episode_timeout_s=12", FAULTS, f"policy.marker_dir={faulty_policy.marker_dir}")
    res = run_evaluation(cfg, fork_servers)
    _check_faults(res, faulty_policy.marker_dir)
    assert "signal SIGKILL" in {r.episode_index: r for r in res.episodes}[1].error
    assert (tmp_path / "run" / "results.json").exists()


@pytest.mark.slow
def test_ray_actors_isolate_crashes_hangs_and_errors(faulty_policy, small_bench, tmp_path, eval_config):
    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "executor=ray", "workers=2", "horizon=3",
                      "episode_timeout_s=12", FAULTS, f"policy.marker_dir={faulty_policy.marker_dir}")
    _check_faults(run_evaluation(cfg), faulty_policy.marker_dir)


@pytest.mark.parametrize("executor", ["local", pytest.param("ray", marks=pytest.mark.slow)])
def test_kill_9_of_one_worker_from_outside_mid_run(executor, faulty_policy, small_bench, tmp_path, eval_config):
    """``kill -9`` a worker while it runs episode 3: that episode reruns, nothing else is lost."""
    markers = faulty_policy.marker_dir
    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "workers=2", "horizon=8",
                      f"executor={executor}", "policy.act_sleep_s=0.05", f"policy.marker_dir={markers}")
    killed: list[int] = []
    stop = threading.Event()

    def killer() -> None:
        while not stop.is_set():
            pids = (markers / "pids-3").read_text().split() if (markers / "pids-3").exists() else []
            if pids:
                pid = int(pids[0])
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                return
            time.sleep(0.01)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    try:
        res = run_evaluation(cfg)
    finally:
        stop.set()
        thread.join()
    assert killed, "the worker running episode 3 was never seen"
    by = {r.episode_index: r for r in res.episodes}
    assert sorted(by) == list(range(8)) and res.summary["n_errors"] == 0
    assert by[3].attempts == 2 and by[3].steps == 8
    assert next(int(p) for p in (markers / "pids-3").read_text().split()) == killed[0]
    assert all(by[i].attempts == 1 for i in by if i != 3)


def test_policy_that_cannot_start_fails_the_run_clearly(faulty_policy, small_bench, tmp_path, eval_config,
                                                         fork_servers):
    from molmo_lerobot.runner.supervisor import WorkerStartError

    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "workers=1", "horizon=2", "policy.fail_init=true")
    with pytest.raises(WorkerStartError, match="refusing to start"):
        run_evaluation(cfg, fork_servers)
    assert not (tmp_path / "run" / "results.json").exists()


@pytest.mark.parametrize("retries", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_replacement_worker_killed_while_starting_is_a_worker_death(retries, faulty_policy, small_bench, tmp_path,
                                                                     eval_config):
    """Episode 1's worker is SIGKILLed; its replacement is SIGKILLed while starting (as an OOM kill
    would). That start-up death is charged to episode 1 like any worker death: with one retry the
    episode is an error, with two it completes; the run goes on either way. One worker slot, so the
    replacement is started for episode 1 (with two, a free slot may take the retry first)."""
    markers = faulty_policy.marker_dir
    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "workers=1", "horizon=3",
                      f"episode_retries={retries}", "+policy.faults={1: sigkill_once}", "+policy.kill_starts=1",
                      f"policy.marker_dir={markers}")
    res = run_evaluation(cfg)
    by = {r.episode_index: r for r in res.episodes}
    assert sorted(by) == list(range(8))
    assert (markers / "start-kills").read_text() == "x", "a replacement worker was killed while starting"
    if retries == 1:
        assert by[1].attempts == 2 and by[1].error == "worker process died with signal SIGKILL while starting"
        assert by[1].task_type == "pick" and by[1].horizon == 3, "an error keeps the episode's task type and horizon"
    else:
        assert by[1].attempts == 3 and by[1].error is None and by[1].steps == 3
    assert res.summary["n_errors"] == (1 if retries == 1 else 0)
    assert all(by[i].attempts == 1 and by[i].error is None for i in by if i != 1)
    assert (tmp_path / "run" / "results.json").exists()


def test_keyboard_interrupt_or_sys_exit_in_a_policy_is_an_episode_error(faulty_policy, small_bench, tmp_path,
                                                                        eval_config, fork_servers):
    markers = faulty_policy.marker_dir
    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "workers=1", "horizon=2", "limit=4",
                      "+policy.faults={1: keyboard_interrupt, 2: system_exit}", f"policy.marker_dir={markers}")
    res = run_evaluation(cfg, fork_servers)
    by = {r.episode_index: r for r in res.episodes}
    assert by[1].error.startswith("KeyboardInterrupt:") and "faulty" not in by[1].error.split("(")[0]
    assert "died" not in by[1].error and by[1].attempts == 1
    assert by[2].error.startswith("SystemExit: 7") and by[2].attempts == 1
    assert by[0].error is None and by[3].error is None
    pids = {(markers / f"pids-{i}").read_text() for i in range(4)}
    assert len(pids) == 1, "the worker lives on after the policy's KeyboardInterrupt / sys.exit"


def _cli_args(bench, out, markers, *extra):
    return [f"benchmark.path={bench}", f"output_dir={out}", "progress=false", "policy=faulty",
            f"policy.marker_dir={markers}", *extra]


def test_molmo_eval_leaves_no_child_process_behind(faulty_policy, small_bench, tmp_path, run_cli):
    report = run_cli(*_cli_args(small_bench, tmp_path / "run", faulty_policy.marker_dir,
                                "workers=2", "limit=2", "horizon=2"))
    assert report["rc"] == 0, report["stderr"]
    assert report["left"] == {}, f"molmo-eval exited before reaping: {report['left']}"


def test_sigterm_stops_workers_keeps_finished_episodes_and_says_how_to_resume(faulty_policy, small_bench, tmp_path,
                                                                              run_cli, eval_config, fork_servers):
    """SIGTERM while episode 0 hangs and others finish: every worker ends, nothing is orphaned, the
    finished episodes stay in episodes.jsonl, the run does not look complete, and resuming finishes it
    without rerunning them."""
    markers, out = faulty_policy.marker_dir, tmp_path / "run"
    extra = ("workers=2", "horizon=3", "policy.act_sleep_s=0.2", "+policy.faults={0: hang_once}")
    report = run_cli(*_cli_args(small_bench, out, markers, *extra), signal=signal.SIGTERM,
                     when=[(out / "episodes.jsonl", 2), (markers / "pids-0", 1)])
    assert report["exit_after_signal_s"] is not None, report["stderr"]
    assert report["rc"] == 128 + signal.SIGTERM, report["stderr"]
    assert report["exit_after_signal_s"] < 15
    assert report["left"] == {}, f"processes left behind: {report['left']}"
    assert "interrupted by SIGTERM" in report["stderr"] and f"output_dir={out} resume=true" in report["stderr"]
    assert not (out / "results.json").exists()
    kept = [json.loads(line)["episode_index"] for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert 2 <= len(kept) < 8 and 0 not in kept
    res = run_evaluation(eval_config(small_bench, out, "policy=faulty", f"policy.marker_dir={markers}",
                                     *extra, "resume=true"), fork_servers)
    assert res.summary["n_episodes"] == 8 and res.summary["n_errors"] == 0
    for i in kept:
        assert len((markers / f"pids-{i}").read_text().split()) == 1, f"finished episode {i} was rerun"


@pytest.mark.slow
def test_ctrl_c_with_a_hung_episode_exits_promptly(faulty_policy, small_bench, tmp_path, run_cli):
    markers, out = faulty_policy.marker_dir, tmp_path / "run"
    report = run_cli(*_cli_args(small_bench, out, markers, "workers=1", "horizon=3", "+policy.faults={1: hang}"),
                     signal=signal.SIGINT, when=[(markers / "hung-1", 0)])
    assert report["rc"] == 128 + signal.SIGINT, report["stderr"]
    assert report["exit_after_signal_s"] < 10, report["exit_after_signal_s"]
    assert "interrupted by SIGINT: 1 of 8 episodes finished" in report["stderr"]
    assert report["left"] == {}


@pytest.mark.slow
def test_workers_of_a_killed_molmo_eval_end_on_their_own(faulty_policy, small_bench, tmp_path, run_cli):
    """``kill -9`` of molmo-eval itself (no handler runs): its workers, one of them hung, notice and end."""
    markers, out = faulty_policy.marker_dir, tmp_path / "run"
    report = run_cli(*_cli_args(small_bench, out, markers, "workers=2", "horizon=3", "+policy.faults={1: hang}"),
                     signal=signal.SIGKILL, when=[(markers / "hung-1", 0)], orphan_grace_s=15)
    assert report["rc"] == -signal.SIGKILL
    running = {pid: s for pid, s in report["left"].items() if s[0] not in ("Z", "gone")}
    assert running == {}, f"workers still running after their supervisor died: {running}"


@pytest.mark.slow
def test_the_policy_server_of_a_killed_molmo_eval_ends_on_its_own(faulty_policy, small_bench, tmp_path, run_cli):
    """Issue 39, defect 5: ``kill -9`` of molmo-eval with ``policy.serve=true`` mid-run: its policy server
    ends as its workers do, and so does the resource tracker it held open, instead of listening on
    (a GPU model holding its memory) under init."""
    markers, out = faulty_policy.marker_dir, tmp_path / "run"
    report = run_cli(*_cli_args(small_bench, out, markers, "workers=1", "horizon=20", "+policy.serve=true",
                                "policy.act_sleep_s=0.1"),
                     signal=signal.SIGKILL, when=[(markers / "pids-1", 1)], orphan_grace_s=40)
    assert report["rc"] == -signal.SIGKILL, report["stderr"]
    assert report["left"], "molmo-eval left no process to check (did the server start?)"
    running = {pid: s for pid, s in report["left"].items() if s[0] not in ("Z", "gone")}
    assert running == {}, f"processes still running after molmo-eval was killed: {running}"


def test_a_failing_export_leaves_the_score_standing(faulty_policy, small_bench, tmp_path, eval_config, fork_servers):
    """Scores first: results.json and episodes.jsonl are final before any export step runs; an export
    that fails is an error that says the score stands and where it is; the report still runs."""
    from molmo_lerobot.errors import ExportError

    out = tmp_path / "run"
    cfg = eval_config(small_bench, out, "policy=faulty", "workers=1", "horizon=2", "limit=3",
                      f"policy.marker_dir={faulty_policy.marker_dir}", f"+trace_dir={tmp_path / 'traces'}",
                      "+trace_fail_finalize=true")
    with pytest.raises(ExportError, match=r"export failed after the run was scored \(export TraceFactory: "
                                          r"OSError: trace export: disk full.*the score stands: 0/3 successes in "
                                          + str(out / "results.json")):
        run_evaluation(cfg, fork_servers)
    summary = json.loads((out / "results.json").read_text())
    assert summary["n_episodes"] == 3 and summary["n_errors"] == 0
    assert summary["export_errors"] == ["export TraceFactory: OSError: trace export: disk full "
                                        "(trace_fail_finalize=true)"], "results.json records the failed export"
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert [r["episode_index"] for r in rows] == [0, 1, 2]
    assert sorted(p.name for p in (tmp_path / "traces").iterdir()) == ["trace-0", "trace-1", "trace-2"]
    assert (out / "report.html").exists(), "the report runs even though an export step failed"


class _ScriptedTransport:
    """An in-memory transport for the supervisor's state machine: each started worker follows the
    next entry of ``starts`` (``ok``, ``die`` while starting, ``init_error``), each attempt of an
    episode the next entry of ``attempts[episode]`` (``ok``, ``die``, ``hang``, ``infra``: a result that is an
    infrastructure failure; default ``ok``)."""

    def __init__(self, starts=(), attempts=None):
        self.starts, self.attempts = list(starts), {k: list(v) for k, v in (attempts or {}).items()}
        self.started, self.stopped = [], []

    def open(self, workers):
        pass

    def close(self):
        pass

    def start(self, worker_id, job):
        handle = {"id": worker_id, "start": self.starts.pop(0) if self.starts else "ok", "ready": False,
                  "item": None, "dead": False}
        self.started.append(worker_id)
        return handle

    def submit(self, handle, item):
        handle["item"] = item

    def wait(self, handles, timeout):
        time.sleep(0.001)

    def events(self, h):
        from molmo_lerobot.runner.supervisor import DEAD, INIT_ERROR, READY, RESULT

        if h["dead"]:
            return []
        if not h["ready"]:
            if h["start"] == "die":
                h["dead"] = True
                return [(DEAD, "signal SIGKILL")]
            if h["start"] == "init_error":
                h["dead"] = True
                return [(INIT_ERROR, "RuntimeError: no GPU")]
            h["ready"] = True
            return [(READY, None)]
        item = h["item"]
        if item is None:
            return []
        todo = self.attempts.get(item.episode_index) or ["ok"]
        what = todo.pop(0) if len(todo) > 1 else todo[0]
        if what == "die":
            h["dead"] = True
            return [(DEAD, "signal SIGKILL")]
        if what == "hang":
            return []
        h["item"] = None
        if what == "infra":
            return [(RESULT, item.failed("SuiteProcessError: suite env x exited (signal SIGKILL)",
                                         "infrastructure").to_dict())]
        return [(RESULT, {"episode_index": item.episode_index, "house_index": 0, "task_cls": "x", "success": True,
                          "success_once": True, "steps": item.horizon, "seed": item.seed})]

    def stop(self, h):
        self.stopped.append(h["id"])
        h["dead"] = True

    def ended(self, h):
        return h["dead"]

    def kill(self, h):
        h["dead"] = True


def _supervise(transport, n, **options):
    from molmo_lerobot.episode_plan import EpisodePlan
    from molmo_lerobot.runner.supervisor import Supervisor

    results = []
    items = [EpisodePlan.of(i, {"house_index": i, "task": {"task_cls": "x"}}, 100 + i, "pick", "", 5, "cli", "")
             for i in range(n)]
    Supervisor(transport, workers=2, **options).run(None, items, results.append)
    return {r.episode_index: r for r in results}, len(results)


def test_supervisor_charges_start_up_deaths_to_the_episode_and_bounds_retries():
    # worker w0 runs episode 0 and dies; its replacement dies while starting: episode 0 is out of retries
    t = _ScriptedTransport(starts=["ok", "ok", "die"], attempts={0: ["die", "ok"]})
    by, n = _supervise(t, 4, retries=1)
    assert n == 4 and sorted(by) == [0, 1, 2, 3], "every episode reported exactly once"
    assert by[0].error == "worker process died with signal SIGKILL while starting" and by[0].attempts == 2
    assert by[0].task_type == "pick" and by[0].horizon == 5 and by[0].seed == 100
    assert all(by[i].error is None and by[i].attempts == 1 for i in (1, 2, 3))


def test_supervisor_retries_an_infrastructure_failure_on_the_worker_that_reported_it():
    """A worker that lives on reports an infrastructure failure (its suite process died): the episode is retried
    as after a worker death, bounded by ``retries``, and only the last attempt's result is reported."""
    t = _ScriptedTransport(attempts={1: ["infra", "ok"], 2: ["infra"]})
    by, n = _supervise(t, 4, retries=1)
    assert n == 4 and by[1].error is None and by[1].attempts == 2
    assert by[2].error_kind == "infrastructure" and by[2].attempts == 2 and "SIGKILL" in by[2].error
    assert by[0].attempts == by[3].attempts == 1 and t.started == ["w0g0", "w1g0"], "no worker replaced"
    by, n = _supervise(_ScriptedTransport(attempts={0: ["infra", "ok"]}), 2, retries=0)
    assert by[0].error_kind == "infrastructure" and by[0].attempts == 1


def test_supervisor_init_error_fails_the_run_only_before_any_worker_started():
    from molmo_lerobot.runner.supervisor import WorkerStartError

    with pytest.raises(WorkerStartError, match="worker could not start: RuntimeError: no GPU"):
        _supervise(_ScriptedTransport(starts=["init_error", "init_error"]), 2)
    t = _ScriptedTransport(starts=["ok", "ok", "init_error"], attempts={1: ["die", "ok"]})
    by, n = _supervise(t, 3, retries=2)
    # one death and one worker that could not start: two more attempts, charged, no error, the run goes on
    assert n == 3 and all(r.error is None for r in by.values()) and sum(r.attempts for r in by.values()) == 5


def test_supervisor_watchdog_records_a_timeout_and_stops_the_worker():
    t = _ScriptedTransport(attempts={1: ["hang"]})
    by, n = _supervise(t, 3, timeout_s=0.2)
    assert n == 3 and by[1].error == "episode timed out after 0.2 s (watchdog)" and by[1].attempts == 1
    assert by[0].error is None and by[2].error is None
    assert "w1g0" in t.stopped, "the hung worker was asked to stop"


def test_the_readme_gives_the_exit_codes_an_interrupted_run_has():
    """An interrupted molmo-eval exits 128 + the signal number (asserted above for SIGTERM and SIGINT),
    as a shell reports a process the signal ended; the README says so for both."""
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert f"{128 + signal.SIGINT} for Ctrl-C/SIGINT, {128 + signal.SIGTERM} for SIGTERM" in readme
