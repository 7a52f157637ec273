"""Process transport: each worker is a local process (spawn or forkserver) with its own pipe.

:class:`LocalExecutor` is the :class:`~molmo_lerobot.runner.supervisor.Supervisor` over it.
A worker ignores SIGINT (the supervisor decides when workers stop); SIGTERM aborts its running
episode, closes its recorders and ends it. A worker whose supervisor process is gone stops the
same way, then exits, so none is left running without one.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from typing import Any

from molmo_lerobot.runner.plan import EpisodePlan
from molmo_lerobot.runner.progress import redirect_worker_output
from molmo_lerobot.runner.supervisor import DEAD, INIT_ERROR, READY, RESULT, Event, Supervisor, Transport, exit_reason
from molmo_lerobot.runner.worker import EpisodeWorker, WorkerJob, WorkerStop

#: Seconds an orphaned worker has to stop gracefully before it exits regardless.
ORPHAN_GRACE_S = 10.0


def _worker_main(conn: Connection, job: WorkerJob, worker_id: str) -> None:
    os.environ.setdefault("MUJOCO_GL", "egl")
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    redirect_worker_output(job.output_dir, worker_id)  # library prints go to logs/, not through the bar
    threading.Thread(target=_exit_when_orphaned, daemon=True).start()
    try:
        worker = EpisodeWorker(job, worker_id)
    except Exception as exc:
        conn.send((INIT_ERROR, f"{type(exc).__name__}: {exc}"))
        return
    signal.signal(signal.SIGTERM, lambda signum, frame: worker.request_stop())
    conn.send((READY, None))
    try:
        while not worker.stopping and (item := conn.recv()) is not None:
            result = worker.run(item)
            conn.send((RESULT, result.to_dict()))
    except (WorkerStop, EOFError, BrokenPipeError, ConnectionResetError):
        pass  # asked to stop, or the supervisor is gone: close our outputs and exit quietly
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # closing is not interrupted twice
        worker.close()


def _exit_when_orphaned() -> None:
    """Stop this worker gracefully (then for sure) once its parent process has gone (the
    supervisor, or with ``forkserver`` the server, which ends with the supervisor)."""
    parent = os.getppid()
    while os.getppid() == parent:
        time.sleep(0.5)
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
    """Workers as local processes of ``start_method`` (``spawn`` or ``forkserver``)."""

    def __init__(self, start_method: str = "spawn") -> None:
        self.ctx = mp.get_context(start_method)

    def start(self, worker_id: str, job: WorkerJob) -> _Worker:
        parent, child = self.ctx.Pipe()
        proc = self.ctx.Process(target=_worker_main, args=(child, job, worker_id),
                                name=f"molmo-{worker_id}", daemon=True)
        proc.start()
        child.close()
        return _Worker(proc, parent)

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
            out.append((DEAD, exit_reason(handle.proc.exitcode)))
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
            with contextlib.suppress(ProcessLookupError):
                os.kill(handle.proc.pid, signal.SIGTERM)  # busy: abort the episode, close and exit

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
    """The supervisor over worker processes: ``LocalExecutor(workers, start_method, timeout_s=…)``."""

    def __init__(self, workers: int, start_method: str = "spawn", **options: Any) -> None:
        super().__init__(ProcessTransport(start_method), workers, **options)
