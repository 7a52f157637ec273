"""Local executor: supervised worker processes, one episode per work item.

Each worker is a separate process (spawn or forkserver) with its own pipe. The supervisor
hands an episode to an idle worker and waits on every pipe and process sentinel at once:

* a result comes back → reported;
* a worker dies mid-episode (SIGKILL, segfault, OOM) → the episode is retried on a fresh
  worker up to ``retries`` times, then recorded as an error; nothing else is lost;
* an episode runs past ``timeout_s`` → its worker is killed and the episode recorded as a
  timeout error; a fresh worker takes its place.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any

from molmo_lerobot.runner.progress import redirect_worker_output
from molmo_lerobot.runner.results import EpisodeResult
from molmo_lerobot.runner.worker import EpisodeWorker, WorkerJob, WorkItem


class WorkerStartError(RuntimeError):
    """A worker could not initialize (e.g. the policy failed to load): the run cannot start."""


def _worker_main(conn: Connection, job: WorkerJob, worker_id: str) -> None:
    os.environ.setdefault("MUJOCO_GL", "egl")
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the supervisor decides when workers stop
    redirect_worker_output(job.output_dir, worker_id)  # library prints go to logs/, not through the bar
    try:
        worker = EpisodeWorker(job, worker_id)
    except Exception as exc:
        conn.send(("init_error", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ready", None))
    try:
        while (item := conn.recv()) is not None:
            conn.send(("result", worker.run(item).to_dict()))
    except (EOFError, BrokenPipeError, ConnectionResetError, KeyboardInterrupt):
        pass  # EOF / broken pipe: the supervisor is gone (killed); close our outputs and exit quietly
    finally:
        worker.close()
    try:
        conn.send(("closed", None))
    except OSError:
        pass


@dataclass
class _Slot:
    index: int
    generation: int
    proc: Any
    conn: Connection
    ready: bool = False
    item: WorkItem | None = None
    started: float = 0.0

    @property
    def worker_id(self) -> str:
        return f"w{self.index}g{self.generation}"


class LocalExecutor:
    """Run work items on ``workers`` supervised processes."""

    def __init__(self, workers: int, start_method: str = "spawn", timeout_s: float = 900.0,
                 retries: int = 1, init_timeout_s: float = 600.0) -> None:
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = workers
        self.ctx = mp.get_context(start_method)
        self.timeout_s = timeout_s
        self.retries = retries
        self.init_timeout_s = init_timeout_s

    def _start(self, index: int, generation: int, job: WorkerJob) -> _Slot:
        parent, child = self.ctx.Pipe()
        slot = _Slot(index, generation, None, parent)
        proc = self.ctx.Process(target=_worker_main, args=(child, job, slot.worker_id),
                                name=f"molmo-{slot.worker_id}", daemon=True)
        proc.start()
        child.close()
        slot.proc, slot.started = proc, time.monotonic()
        return slot

    def run(self, job: WorkerJob, items: list[WorkItem], on_result: Callable[[EpisodeResult], None]) -> None:
        if not items:
            return
        pending: deque[WorkItem] = deque(items)
        attempts: dict[int, int] = {}
        slots = [self._start(i, 0, job) for i in range(min(self.workers, len(items)))]
        try:
            while pending or any(s.item is not None for s in slots):
                for slot in slots:
                    if slot.ready and slot.item is None and pending:
                        slot.item, slot.started = pending.popleft(), time.monotonic()
                        attempts[slot.item.episode_index] = attempts.get(slot.item.episode_index, 0) + 1
                        slot.conn.send(slot.item)
                waitables = [s.conn for s in slots] + [s.proc.sentinel for s in slots]
                wait(waitables, timeout=1.0)
                for i, slot in enumerate(slots):
                    slots[i] = self._poll(slot, job, pending, attempts, on_result)
        finally:
            self._shutdown(slots)

    def _poll(self, slot: _Slot, job: WorkerJob, pending: deque[WorkItem], attempts: dict[int, int],
              on_result: Callable[[EpisodeResult], None]) -> _Slot:
        """Handle whatever happened to one worker; returns the slot (a fresh one if it was replaced)."""
        try:
            while slot.conn.poll():
                kind, payload = slot.conn.recv()
                if kind == "ready":
                    slot.ready = True
                elif kind == "init_error":
                    raise WorkerStartError(f"worker could not start: {payload}")
                elif kind == "result":
                    result = EpisodeResult.from_dict(payload)
                    result.attempts = attempts.get(result.episode_index, 1)
                    on_result(result)
                    slot.item = None
        except (EOFError, ConnectionResetError, BrokenPipeError):
            pass
        now = time.monotonic()
        if not slot.proc.is_alive():
            code = slot.proc.exitcode
            if not slot.ready:
                raise WorkerStartError(f"worker process exited with {_exit_reason(code)} while starting")
            if slot.item is not None:
                item = slot.item
                reason = f"worker process died with {_exit_reason(code)} during the episode"
                if attempts[item.episode_index] <= self.retries:
                    pending.appendleft(item)
                else:
                    on_result(_failure(item, reason, attempts[item.episode_index]))
            return self._replace(slot, job)
        if slot.item is not None and now - slot.started > self.timeout_s:
            item = slot.item
            slot.proc.kill()
            slot.proc.join(5)
            on_result(_failure(item, f"episode timed out after {self.timeout_s:g} s (watchdog)",
                               attempts[item.episode_index]))
            return self._replace(slot, job)
        if not slot.ready and now - slot.started > self.init_timeout_s:
            raise WorkerStartError(f"worker did not start within {self.init_timeout_s:g} s")
        return slot

    def _replace(self, slot: _Slot, job: WorkerJob) -> _Slot:
        slot.conn.close()
        return self._start(slot.index, slot.generation + 1, job)

    def _shutdown(self, slots: list[_Slot]) -> None:
        for slot in slots:
            try:
                if slot.proc.is_alive():
                    slot.conn.send(None)
            except (BrokenPipeError, OSError):
                pass
        deadline = time.monotonic() + 120
        for slot in slots:
            slot.proc.join(max(0.1, deadline - time.monotonic()))
            if slot.proc.is_alive():
                slot.proc.kill()
                slot.proc.join(5)
            slot.conn.close()


def _failure(item: WorkItem, reason: str, attempts: int) -> EpisodeResult:
    spec = item.spec
    task = spec.get("task") if isinstance(spec.get("task"), dict) else {}
    return EpisodeResult.failed(item.episode_index, spec.get("house_index"), task.get("task_cls"),
                                item.seed, reason, attempts=attempts)


def _exit_reason(code: int | None) -> str:
    if code is not None and code < 0:
        try:
            return f"signal {signal.Signals(-code).name}"
        except ValueError:
            return f"signal {-code}"
    return f"exit code {code}"
