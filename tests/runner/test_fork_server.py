"""Issue 39, defects 3 and 4: a worker's liveness never depends on the run's fork server. A stopped
(SIGSTOP) server neither hides a worker's death nor holds up the next start; a killed one neither
fakes the death of a live worker nor fails the next start (a fresh server replaces it).

The cheap check drives :class:`PreloadedForkServer` with processes that only sleep; the slow ones run
``run_evaluation`` and stop or kill the server of a real run, whose transport replaces it."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import threading
import time
from multiprocessing.connection import Pipe
from pathlib import Path

import pytest

from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.runner.forkserver import ForkServerLost, ForkServerPool, PreloadedForkServer, exit_status_lost
from molmo_lerobot.runner.local import ProcessTransport, _Worker
from molmo_lerobot.runner.supervisor import DEAD

#: generous bounds for a loaded 2-core machine; each wait returns as soon as its condition holds
WAIT_S = 60


def _until(condition, timeout_s=WAIT_S, every_s=0.05):
    deadline = time.monotonic() + timeout_s
    while not (got := condition()):
        if time.monotonic() > deadline:
            return got
        time.sleep(every_s)
    return got


def _state(pid: int) -> str:
    """``R``, ``S``, ``T``, ``Z``, ... from ``/proc``; ``gone`` when there is no such process."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"


@pytest.fixture
def server():
    """A fork server with nothing preloaded; what it started is killed afterwards (``srv.started``)."""
    srv = PreloadedForkServer([])
    srv.started = []
    srv.start()
    yield srv
    for proc in srv.started:
        with contextlib.suppress(ProcessLookupError):
            os.kill(proc.pid, signal.SIGKILL)
    if srv.pid is not None:
        os.kill(srv.pid, signal.SIGCONT)
    srv.stop()


def _sleeper(srv: PreloadedForkServer, name: str = "sleeper"):
    proc = srv.process(time.sleep, (300,), name=name)
    proc.start()
    srv.started.append(proc)
    assert proc.is_alive()
    return proc


def test_a_stopped_fork_server_hides_no_death_and_a_killed_one_fakes_none(server):
    """The cheap default check of both defects, on the transport's own view of a worker."""
    transport = ProcessTransport("forkserver")
    victim, survivor = _sleeper(server, "victim"), _sleeper(server, "survivor")
    pipes = [Pipe(), Pipe()]  # both ends held: only the process can wake the wait
    handles = [_Worker(p, pipe[0]) for p, pipe in zip((victim, survivor), pipes, strict=True)]
    first = server.pid
    os.kill(first, signal.SIGSTOP)
    assert _until(lambda: _state(first) == "T"), "the fork server did not stop"
    os.kill(victim.pid, signal.SIGKILL)
    t0 = time.monotonic()
    transport.wait(handles, timeout=30)  # the victim's pidfd wakes it, however the server is
    events = _until(lambda: transport.events(handles[0]), timeout_s=30)
    assert events == [(DEAD, "an exit status its lost fork server never reported")], \
        "a worker's death went unnoticed while its fork server was stopped"
    assert time.monotonic() - t0 < 30 and exit_status_lost(victim)
    # a start from the stopped server fails at once instead of waiting on it forever
    with pytest.raises(ForkServerLost, match=rf"the worker fork server \(process {first}\) is stopped"):
        _sleeper(server, "never")
    server.restart()
    replacement = _sleeper(server, "replacement")
    assert server.pid != first and _state(first) == "gone"
    # the server that forked the survivor is gone: the survivor is alive all the same
    assert survivor.is_alive() and transport.events(handles[1]) == []
    second = server.pid
    os.kill(second, signal.SIGKILL)
    assert _until(lambda: _state(second) in ("Z", "gone"))
    assert survivor.is_alive() and replacement.is_alive(), "a live worker was reported dead"
    again = _sleeper(server, "after the kill")  # a dead server is replaced when asked to fork
    assert server.pid != second
    for proc in (survivor, replacement, again):
        proc.kill()
        proc.join(WAIT_S)
    assert replacement.exitcode == 255 and exit_status_lost(replacement)  # its server was killed
    assert again.exitcode == -signal.SIGKILL and not exit_status_lost(again)  # its server reaped it


def test_a_pool_lends_a_running_server_of_the_same_origin_only(monkeypatch):
    """A server given back is lent again to a run of the same preload and environment, never to another;
    one killed while idle or stopped while lent is killed and replaced, never lent; at most ``keep``
    idle servers are kept, and closing the pool ends them. Variables it was told to ignore do not count."""
    with ForkServerPool(keep=1, ignored_env=["MOLMO_POOL_IGNORED"]) as pool:
        first = pool.borrow([])
        first.started = []
        _sleeper(first).kill()
        pool.give_back(first)
        monkeypatch.setenv("MOLMO_POOL_IGNORED", "any")
        assert pool.borrow([]) is first  # the same origin: the same running server
        monkeypatch.setenv("MOLMO_POOL_TEST", "other")
        other = pool.borrow([])  # another environment: another server, the first still lent
        evicted = other.pid
        assert evicted not in (None, first.pid)
        pool.give_back(other)
        pool.give_back(first)  # keep=1: the one idle longer (other) is stopped
        assert _state(evicted) == "gone"
        monkeypatch.delenv("MOLMO_POOL_TEST")
        lost = first.pid
        os.kill(lost, signal.SIGKILL)  # lost while idle
        assert _until(lambda: _state(lost) in ("Z", "gone"))
        fresh = pool.borrow([])
        assert fresh.pid not in (None, lost) and fresh.state() is None
        fresh.started = []
        _sleeper(fresh).kill()  # it forks
        stopped = fresh.pid
        os.kill(stopped, signal.SIGSTOP)  # stopped while lent: given back, it is killed, not kept
        assert _until(lambda: _state(stopped) == "T")
        pool.give_back(fresh)
        assert _state(stopped) in ("Z", "gone")
        kept = pool.borrow([])
        assert kept.pid != stopped
        pool.give_back(kept)
        last = kept.pid
    assert _until(lambda: _state(last) == "gone"), "closing the pool left its server running"


# -- a real run ---------------------------------------------------------------------------------------------------
def _fork_server_of(pid: int) -> int:
    """A forked worker's parent: the run's fork server."""
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def _worker_pid(markers: Path, episode: int) -> int | None:
    path = markers / f"pids-{episode}"
    pids = path.read_text().split() if path.exists() else []
    return int(pids[0]) if pids else None


def _rows(out: Path) -> dict[int, dict]:
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    return {r["episode_index"]: r for r in rows}


@pytest.mark.slow
@pytest.mark.parametrize("retries", [0, 1])
def test_a_worker_killed_under_a_stopped_fork_server_is_an_infrastructure_death(
        retries, faulty_policy, small_bench, tmp_path, eval_config):
    """SIGSTOP the fork server, then SIGKILL the worker running episode 1: the death is seen at once
    (long before the watchdog), retried on a worker from a fresh server, or with ``retries=0``
    recorded as an infrastructure error (resume runs it again), never as an episode timeout."""
    markers, out = faulty_policy.marker_dir, tmp_path / "run"
    cfg = eval_config(small_bench, out, "policy=faulty", "workers=1", "horizon=40", "limit=3",
                      "policy.act_sleep_s=0.05", f"policy.marker_dir={markers}", "episode_timeout_s=120",
                      f"episode_retries={retries}")
    done: dict[str, int] = {}

    def saboteur() -> None:
        worker = _until(lambda: _worker_pid(markers, 1), timeout_s=300)
        if worker is None:
            return
        server = done["server"] = _fork_server_of(worker)
        os.kill(server, signal.SIGSTOP)
        _until(lambda: _state(server) == "T")
        os.kill(worker, signal.SIGKILL)
        done["worker"] = worker

    thread = threading.Thread(target=saboteur, daemon=True)
    thread.start()
    # should the run wait on the stopped server (the defect), let it go on after the watchdog fired
    resume = threading.Timer(180, lambda: "server" in done and os.kill(done["server"], signal.SIGCONT))
    resume.start()
    try:
        res = run_evaluation(cfg)
    finally:
        resume.cancel()
    thread.join(5)
    assert "worker" in done, "the saboteur never found episode 1's worker"
    by = {r.episode_index: r for r in res.episodes}
    assert sorted(by) == [0, 1, 2] and by[0].error is None and by[2].error is None
    rows = _rows(out)
    if retries:
        assert by[1].error is None and by[1].attempts == 2
    else:
        assert by[1].error == ("worker process died with an exit status its lost fork server never reported "
                               "during the episode")
        assert rows[1]["error_kind"] == "infrastructure" and by[1].attempts == 1


@pytest.mark.slow
def test_kill_9_of_the_fork_server_mid_run_costs_no_episode(faulty_policy, small_bench, tmp_path, eval_config):
    """``kill -9`` of the fork server while two workers run: they are not reported dead, and the
    worker started after one of them is killed comes from a fresh server; every episode ends on its
    first attempt but the killed worker's, and none is an error (it was 2 retried episodes, or the
    run ending with exit 2 when the next start raced the dying server)."""
    markers, out = faulty_policy.marker_dir, tmp_path / "run"
    cfg = eval_config(small_bench, out, "policy=faulty", "workers=2", "horizon=20", "limit=6",
                      "policy.act_sleep_s=0.05", f"policy.marker_dir={markers}", "episode_retries=1")
    done: dict[str, int] = {}

    def saboteur() -> None:
        worker = _until(lambda: _worker_pid(markers, 1), timeout_s=300)
        if worker is None:
            return
        server = _fork_server_of(worker)
        os.kill(server, signal.SIGKILL)
        done["server"] = server
        time.sleep(1.0)  # the supervisor sees the server's status pipes close meanwhile
        killed = _until(lambda: _worker_pid(markers, 4) or _worker_pid(markers, 3), timeout_s=300)
        if killed is not None:
            os.kill(killed, signal.SIGKILL)  # its replacement must come from a fresh server
            done["worker"] = killed

    thread = threading.Thread(target=saboteur, daemon=True)
    thread.start()
    res = run_evaluation(cfg)
    thread.join(5)
    assert "server" in done and "worker" in done, done
    by = {r.episode_index: r for r in res.episodes}
    assert sorted(by) == list(range(6)) and all(r.error is None for r in by.values()), \
        {i: r.error for i, r in by.items()}
    retried = [i for i, r in by.items() if r.attempts > 1]  # the killed worker's episode (none if it was idle)
    assert len(retried) <= 1 and all(by[i].attempts == 2 for i in retried), "a live worker was reported dead"


def test_runs_sharing_a_pool_fork_from_one_server_and_a_lost_one_is_replaced(
        faulty_policy, small_bench, tmp_path, eval_config, outcomes):
    """Two runs given one pool fork their workers from the same server, with the outcomes of a run that
    started its own; a server killed between runs is replaced, never lent, and costs the next run nothing."""
    markers = faulty_policy.marker_dir
    common = ["policy=faulty", "workers=1", "horizon=3", "limit=2", f"policy.marker_dir={markers}"]

    def parents() -> list[int]:
        return [int(line) for line in (markers / "parents-0").read_text().split()]

    own = run_evaluation(eval_config(small_bench, tmp_path / "own", *common))
    with ForkServerPool() as pool:
        runs = [run_evaluation(eval_config(small_bench, tmp_path / "first", *common), pool),
                run_evaluation(eval_config(small_bench, tmp_path / "second", *common), pool)]
        assert parents()[1] == parents()[2], "the second run started a fork server of its own"
        os.kill(parents()[2], signal.SIGKILL)  # the idle server is lost
        assert _until(lambda: _state(parents()[2]) in ("Z", "gone"))
        runs.append(run_evaluation(eval_config(small_bench, tmp_path / "third", *common), pool))
        assert parents()[3] not in parents()[:3]
    assert _until(lambda: _state(parents()[3]) == "gone"), "closing the pool left its server running"
    for res, name in zip(runs, ("first", "second", "third"), strict=True):
        assert [(r.episode_index, r.success, r.error) for r in res.episodes] == \
            [(r.episode_index, r.success, r.error) for r in own.episodes]
        assert outcomes(tmp_path / name) == outcomes(tmp_path / "own")
