"""Crash isolation: SIGKILLed, hung and raising episodes never take other episodes down."""

from __future__ import annotations

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


def test_local_pool_isolates_crashes_hangs_and_errors(faulty_policy, small_bench, tmp_path, eval_config):
    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "workers=2", "horizon=3",
                      "episode_timeout_s=5", FAULTS, f"policy.marker_dir={faulty_policy.marker_dir}")
    res = run_evaluation(cfg)
    _check_faults(res, faulty_policy.marker_dir)
    assert "signal SIGKILL" in {r.episode_index: r for r in res.episodes}[1].error
    assert (tmp_path / "run" / "results.json").exists()


@pytest.mark.slow
def test_ray_actors_isolate_crashes_hangs_and_errors(faulty_policy, small_bench, tmp_path, eval_config):
    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "executor=ray", "workers=2", "horizon=3",
                      "episode_timeout_s=5", FAULTS, f"policy.marker_dir={faulty_policy.marker_dir}")
    _check_faults(run_evaluation(cfg), faulty_policy.marker_dir)


def test_kill_9_of_one_worker_from_outside_mid_run(faulty_policy, small_bench, tmp_path, eval_config):
    """``kill -9`` a worker while it runs episode 3: that episode reruns, nothing else is lost."""
    markers = faulty_policy.marker_dir
    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "workers=2", "horizon=8",
                      "policy.act_sleep_s=0.05", f"policy.marker_dir={markers}")
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
    assert [int(p) for p in (markers / "pids-3").read_text().split()][0] == killed[0]
    assert all(by[i].attempts == 1 for i in by if i != 3)


def test_policy_that_cannot_start_fails_the_run_clearly(faulty_policy, small_bench, tmp_path, eval_config):
    from molmo_lerobot.runner.supervisor import WorkerStartError

    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "workers=1", "horizon=2", "policy.fail_init=true")
    with pytest.raises(WorkerStartError, match="refusing to start"):
        run_evaluation(cfg)
    assert not (tmp_path / "run" / "results.json").exists()
