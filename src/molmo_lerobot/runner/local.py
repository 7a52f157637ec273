"""Process transport: each worker is a local process with its own pipe.

``start_method`` ``forkserver`` (the default where the platform has it) forks every worker from the
run's :class:`~molmo_lerobot.runner.forkserver.PreloadedForkServer`, which imported MuJoCo, the
harness, the plugins and the policy's libraries once; ``spawn`` starts each worker as a fresh
interpreter that imports them itself. Both import the same modules before building the worker, and
both give the same per-episode outcomes; each worker reports where its start-up went
(:class:`~molmo_lerobot.runner.worker.Startup`, in its log and the run's ``results.json``).

:class:`LocalExecutor` is the :class:`~molmo_lerobot.runner.supervisor.Supervisor` over it.
A worker ignores SIGINT (the supervisor decides when workers stop); SIGTERM aborts its running
episode, closes its recorders and ends it. A worker whose supervisor process is gone stops the
same way, then exits, so none is left running without one. The supervisor sees a forked worker
end through a pidfd, whatever became of the fork server; a server lost (killed, stopped) is
replaced at the next worker start, once per start.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import logging
import multiprocessing as mp
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from multiprocessing.context import ForkServerContext, SpawnContext
from typing import Any

from molmo_lerobot.episode_plan import EpisodePlan
from molmo_lerobot.gl import use_headless_gl
from molmo_lerobot.runner.forkserver import (
    START_METHODS,
    ForkServerPool,
    PreloadedForkServer,
    exit_status_lost,
    inherited_gpu_state,
)
from molmo_lerobot.runner.progress import redirect_worker_output
from molmo_lerobot.runner.supervisor import (
    DEAD,
    INIT_ERROR,
    READY,
    RESULT,
    STARTUP,
    Event,
    Supervisor,
    Transport,
    WorkerStartError,
    exit_reason,
)
from molmo_lerobot.runner.worker import EpisodeWorker, Startup, WorkerJob, WorkerStop

log = logging.getLogger(__name__)

#: Seconds an orphaned worker has to stop gracefully before it exits regardless.
ORPHAN_GRACE_S = 10.0


def _worker_main(conn: Connection, job: WorkerJob, worker_id: str, started_at: float) -> None:
    launch_s = time.time() - started_at  # process start, and for spawn the imports of unpickling this job
    inherited = inherited_gpu_state()
    use_headless_gl()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    redirect_worker_output(job.output_dir, worker_id)  # library prints go to logs/, not through the bar
    threading.Thread(target=_exit_when_orphaned, daemon=True).start()
    startup = Startup(launch_s=launch_s)
    try:
        if inherited:
            raise RuntimeError(f"worker process started holding {inherited} of its parent (it must create its own)")
        with startup.phase("imports_s"):  # already there when forked from the fork server
            for module in job.preload:
                with contextlib.suppress(ImportError):  # as the fork server: whoever needs it says why
                    importlib.import_module(module)
        worker = EpisodeWorker(job, worker_id, startup)
    except Exception as exc:
        conn.send((INIT_ERROR, f"{type(exc).__name__}: {exc}"))
        return
    signal.signal(signal.SIGTERM, lambda signum, frame: worker.request_stop())
    conn.send((READY, None))
    reported = False
    try:
        while not worker.stopping and (item := conn.recv()) is not None:
            result = worker.run(item)
            if worker.first_done and not reported:  # before the result: the run may end with it
                reported = True
                conn.send((STARTUP, startup.report()))
                print(f"{worker_id} start-up (s): {json.dumps(startup.report())}", flush=True)  # to its log
            conn.send((RESULT, result.to_dict()))
    except (WorkerStop, EOFError, BrokenPipeError, ConnectionResetError):
        pass  # asked to stop, or the supervisor is gone: close our outputs and exit quietly
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # closing is not interrupted twice
        worker.close()


def _exit_when_orphaned() -> None:
    """Stop this worker gracefully (then for sure) once the supervisor process that started it
    has gone. That is its parent with ``spawn``; with ``forkserver`` its parent is the server,
    which lives while any worker does, so the supervisor's end is read from multiprocessing's
    parent sentinel (a pipe only the supervisor writes to: it reads EOF once the supervisor is gone)."""
    parent = mp.parent_process()
    if parent is None:
        raise RuntimeError("a worker watches the supervisor that started it: run it in a child process")
    wait([parent.sentinel])
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(ORPHAN_GRACE_S)
    os._exit(1)


@dataclass
class _Worker:
    proc: Any
    conn: Connection
    dead: bool = False
    events: list[Event] = field(default_factory=list)


class ProcessTransport(Transport):
    """Workers as local processes of ``start_method``: ``forkserver`` (forked from the run's
    preloaded fork server, started with the first worker, or borrowed from ``fork_servers`` and
    given back there at the end) or ``spawn``."""

    def __init__(self, start_method: str = "forkserver", fork_servers: ForkServerPool | None = None) -> None:
        if start_method not in START_METHODS:
            raise ValueError(f"executor.start_method: expected one of {list(START_METHODS)}, got {start_method!r}")
        if start_method == "forkserver" and start_method not in mp.get_all_start_methods():
            start_method = "spawn"  # the platform has no fork server
        self.start_method = start_method
        self.ctx: SpawnContext | ForkServerContext = (mp.get_context("spawn") if start_method == "spawn"
                                                       else mp.get_context("forkserver"))
        self.server: PreloadedForkServer | None = None
        self.fork_servers = fork_servers

    def start(self, worker_id: str, job: WorkerJob) -> _Worker:
        parent, child = self.ctx.Pipe()
        args = (child, job, worker_id, time.time())
        try:
            if self.start_method == "forkserver":
                proc = self._fork(args, worker_id, job)
            else:
                proc = self.ctx.Process(target=_worker_main, args=args, name=f"molmo-{worker_id}", daemon=True)
                proc.start()
        finally:
            child.close()
        return _Worker(proc, parent)

    def _fork(self, args: tuple[Any, ...], worker_id: str, job: WorkerJob) -> Any:
        """Start the worker from the fork server; a server lost since it last forked (killed, stopped)
        is replaced by a fresh one, once. One that cannot fork at all (a preloaded module crashed it)
        cannot start any worker."""
        if self.server is None:
            if self.fork_servers is not None:
                self.server = self.fork_servers.borrow(job.preload)
            else:
                self.server = PreloadedForkServer(job.preload)
                self.server.start()
        for attempt in (0, 1):
            proc = self.server.process(_worker_main, args, name=f"molmo-{worker_id}")
            try:
                proc.start()
                return proc
            except (OSError, EOFError) as exc:
                if attempt or not self.server.forked:
                    raise WorkerStartError(f"the worker fork server could not start worker {worker_id} "
                                           f"({type(exc).__name__}: {exc}); "
                                           "executor.start_method=spawn starts workers without it") from None
                log.warning("the worker fork server was lost (%s); starting a fresh one", exc)
                self.server.restart()
        raise AssertionError("unreachable")

    def close(self) -> None:
        if self.server is not None:
            if self.fork_servers is not None:
                self.fork_servers.give_back(self.server)
            else:
                self.server.stop()
            self.server = None

    def submit(self, handle: _Worker, item: EpisodePlan) -> None:
        with contextlib.suppress(OSError):  # it died: its sentinel says so
            handle.conn.send(item)

    def wait(self, handles: list[_Worker], timeout: float) -> None:
        live = [h for h in handles if not h.dead]
        wait([h.conn for h in live] + [h.proc.sentinel for h in live], timeout=timeout)

    def events(self, handle: _Worker) -> list[Event]:
        if handle.dead:
            return []
        out = self._drain(handle)
        if not handle.proc.is_alive():
            out += self._drain(handle)  # what it sent just before it ended
            handle.proc.join()
            handle.dead = True
            handle.conn.close()
            lost = exit_status_lost(handle.proc)
            out.append((DEAD, "an exit status its lost fork server never reported" if lost
                        else exit_reason(handle.proc.exitcode)))
        return out

    @staticmethod
    def _drain(handle: _Worker) -> list[Event]:
        out: list[Event] = []
        try:
            while handle.conn.poll():
                out.append(handle.conn.recv())
        except (EOFError, ConnectionResetError, BrokenPipeError, OSError):
            pass
        return out

    def stop(self, handle: _Worker) -> None:
        with contextlib.suppress(OSError):
            handle.conn.send(None)  # idle: close and exit
        if handle.proc.is_alive():
            handle.proc.terminate()  # SIGTERM, busy: abort the episode, close and exit

    def ended(self, handle: _Worker) -> bool:
        if handle.proc.is_alive():
            return False
        handle.proc.join()
        handle.conn.close()
        handle.dead = True
        return True

    def kill(self, handle: _Worker) -> None:
        if handle.proc.is_alive():
            handle.proc.kill()
        handle.proc.join()
        handle.conn.close()
        handle.dead = True


class LocalExecutor(Supervisor):
    """The supervisor over worker processes: ``LocalExecutor(workers, start_method, fork_servers, timeout_s=…)``."""

    def __init__(self, workers: int, start_method: str = "forkserver", fork_servers: ForkServerPool | None = None,
                 **options: Any) -> None:
        super().__init__(ProcessTransport(start_method, fork_servers), workers, **options)
