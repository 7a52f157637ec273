"""The one episode supervisor: slots, dispatch, bounded retry, watchdog, graceful stop.

A :class:`Supervisor` runs work items (episode plans) on ``workers`` slots. A slot holds one worker at a time,
started by a :class:`Transport` (worker processes in ``runner/local.py``, Ray actors in
``runner/ray_executor.py``) only when it has an episode to run; each start is charged to that
episode. For every slot the supervisor waits on the transport and reacts:

* a result comes back → reported through ``on_result``;
* the worker dies (SIGKILL, segfault, OOM, node loss), during an episode or while starting →
  the episode is retried on a fresh worker up to ``retries`` times, then recorded as an
  infrastructure error naming the death (``resume=true`` runs it again); the run goes on;
* a result is an infrastructure failure (the worker lives on: its suite process died or hung and
  is replaced, a full disk, a lost policy server) → the episode is retried on that slot the same way;
* a slot is free → it gets the pending item that follows its previous one in run order, else
  the start of the longest run of pending items that no slot continues (or that run's second
  half), so each worker plays stretches of consecutive episodes and its dataset shards are in
  benchmark order (see :func:`take_next`);
* a worker cannot start (its policy raised, or it did not start within ``init_timeout_s``)
  before any worker ever started → :class:`WorkerStartError` (nothing can run); later, such a
  start is treated like a death;
* an episode runs past ``timeout_s`` (the watchdog) → it is recorded as a timeout error and its
  worker asked to stop (recorders flush what earlier episodes saved), killed after a grace time.

SIGINT and SIGTERM to the main process (when the supervisor runs in its main thread) stop the
run: running episodes are aborted, idle workers close their recorders, every worker is ended
within ``stop_timeout_s`` and :class:`RunInterrupted` is raised. Finished episodes have
already been reported, so nothing finished is lost.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from molmo_lerobot.episode_plan import EpisodePlan
from molmo_lerobot.errors import INFRASTRUCTURE, MolmoError
from molmo_lerobot.results import EpisodeResult
from molmo_lerobot.runner.worker import WorkerJob

log = logging.getLogger(__name__)

#: Events a transport reports for one worker, in the order they happened (``STARTUP``: where its
#: start-up went, seconds per phase, once, just before its first episode's result; transports may omit it).
READY, INIT_ERROR, RESULT, DEAD, STARTUP = "ready", "init_error", "result", "dead", "startup"
Event = tuple[str, Any]


class WorkerStartError(MolmoError, RuntimeError):
    """No worker could start (e.g. the policy failed to load): the run cannot start."""


class RunInterrupted(KeyboardInterrupt):
    """The run was stopped by SIGINT or SIGTERM after its workers were ended."""

    def __init__(self, signum: int, message: str = "") -> None:
        super().__init__(message or f"interrupted by {signal.Signals(signum).name}")
        self.signum = signum


class Transport(ABC):
    """How workers are started and talked to. Handles are opaque to the supervisor."""

    def open(self, workers: int) -> None:  # noqa: B027 - optional hook: does nothing unless overridden
        """Prepare to start up to ``workers`` workers (e.g. join a cluster)."""

    def close(self) -> None:  # noqa: B027 - optional hook: does nothing unless overridden
        """Every worker has ended: release what ``open`` acquired."""

    @abstractmethod
    def start(self, worker_id: str, job: WorkerJob) -> Any:
        """Start one worker (non-blocking); it reports ``READY`` or ``INIT_ERROR`` when done."""

    @abstractmethod
    def submit(self, handle: Any, item: EpisodePlan) -> None:
        """Hand ``item`` to the worker (it runs once the worker is ready)."""

    @abstractmethod
    def wait(self, handles: list[Any], timeout: float) -> None:
        """Block until one of ``handles`` may have an event, or ``timeout`` seconds."""

    @abstractmethod
    def events(self, handle: Any) -> list[Event]:
        """Drain what happened to the worker; ``DEAD`` (with a reason) comes last and only once."""

    @abstractmethod
    def stop(self, handle: Any) -> None:
        """Ask the worker to end: abort its episode if it runs one, close its recorders, exit."""

    @abstractmethod
    def ended(self, handle: Any) -> bool:
        """Whether the worker has ended and its resources are released."""

    @abstractmethod
    def kill(self, handle: Any) -> None:
        """End the worker now (it may lose its open recorder output)."""


@dataclass
class _Slot:
    index: int
    generation: int = -1  # counts the workers this slot started
    handle: Any = None
    ready: bool = False
    item: EpisodePlan | None = None
    last: int | None = None  # run-order position of the last item this slot was given
    since: float = 0.0  # start of the worker (not ready yet) or of the episode (ready)

    @property
    def worker_id(self) -> str:
        return f"w{self.index}g{self.generation}"


def take_next(pending: dict[int, EpisodePlan], last: int | None, others: list[int | None]) -> int:
    """The run-order position a free slot takes next: the one after its ``last``; else the start
    of the longest run of consecutive pending positions, or its middle when another slot's next
    item starts it (``others``: the other slots' last positions)."""
    if last is not None and last + 1 in pending:
        return last + 1
    continued = {o + 1 for o in others if o is not None}
    best: list[int] = []
    run: list[int] = []
    for p in sorted(pending):
        if run and p != run[-1] + 1:
            best, run = max(best, run, key=len), []
        run.append(p)
    best = max(best, run, key=len)
    return best[len(best) // 2] if best[0] in continued else best[0]


class Supervisor:
    """Run work items on ``workers`` slots of ``transport`` (see the module docstring)."""

    def __init__(self, transport: Transport, workers: int, timeout_s: float = 900.0, retries: int = 1,
                 init_timeout_s: float = 600.0, stop_timeout_s: float = 10.0, close_timeout_s: float = 120.0) -> None:
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.transport = transport
        self.workers = workers
        self.timeout_s = timeout_s
        self.retries = retries
        self.init_timeout_s = init_timeout_s
        self.stop_timeout_s = stop_timeout_s
        self.close_timeout_s = close_timeout_s

    def run(self, job: WorkerJob, items: list[EpisodePlan], on_result: Callable[[EpisodeResult], None],
            on_startup: Callable[[str, dict[str, float]], None] | None = None) -> None:
        """Run every item; each ends in exactly one ``on_result`` call unless the run is interrupted.
        ``on_startup(worker_id, phases)`` gets each worker's start-up breakdown (``STARTUP``)."""
        if not items:
            return
        self._job, self._on_result = job, on_result
        self._on_startup = on_startup
        self._position = {item.episode_index: k for k, item in enumerate(items)}
        self._pending: dict[int, EpisodePlan] = dict(enumerate(items))  # by run-order position
        self._attempts: dict[int, int] = {}
        self._retiring: list[tuple[Any, float]] = []  # stopped workers and when to kill them
        self._any_ready = False
        self._slots = [_Slot(i) for i in range(min(self.workers, len(items)))]
        self.transport.open(len(self._slots))
        interrupted = False
        try:
            with _stop_signals() as stop:
                while self._pending or any(s.item is not None for s in self._slots):
                    if stop.signum is not None:
                        interrupted = True
                        self._shutdown(self.stop_timeout_s, stop)
                        raise RunInterrupted(stop.signum)
                    self._dispatch()
                    live = [s.handle for s in self._slots if s.handle is not None]
                    self.transport.wait(live + [h for h, _ in self._retiring], timeout=0.5)
                    for slot in self._slots:
                        self._poll(slot)
                    self._reap_retiring()
                self._shutdown(self.close_timeout_s, stop)
                if stop.signum is not None:  # stopped while workers were closing: say so
                    interrupted = True
                    raise RunInterrupted(stop.signum)
        except BaseException:
            if not interrupted:
                self._shutdown(self.stop_timeout_s, None)
            raise
        finally:
            self.transport.close()

    # Dispatch and events ------------------------------------------------------------------
    def _dispatch(self) -> None:
        for slot in self._slots:
            if slot.item is not None or not self._pending:
                continue
            slot.last = take_next(self._pending, slot.last, [s.last for s in self._slots if s is not slot])
            item = slot.item = self._pending.pop(slot.last)
            self._attempts[item.episode_index] = self._attempts.get(item.episode_index, 0) + 1
            if slot.handle is None:
                slot.generation += 1
                slot.handle, slot.ready = self.transport.start(slot.worker_id, self._job), False
            slot.since = time.monotonic()
            self.transport.submit(slot.handle, item)

    def _poll(self, slot: _Slot) -> None:
        if slot.handle is None:
            return
        for kind, payload in self.transport.events(slot.handle):
            if kind == READY:
                slot.ready, slot.since, self._any_ready = True, time.monotonic(), True
            elif kind == RESULT:
                self._report(slot, EpisodeResult.from_dict(payload))
            elif kind == STARTUP:
                if self._on_startup is not None:
                    self._on_startup(slot.worker_id, payload)
            elif kind == INIT_ERROR:
                if not self._any_ready:
                    raise WorkerStartError(f"worker could not start: {payload}")
                self._lost(slot, f"worker could not start: {payload}", stop=True)
                return
            elif kind == DEAD:
                self._lost(slot, f"worker process died with {payload}"
                           + (" during the episode" if slot.ready else " while starting"))
                return
        now = time.monotonic()
        if not slot.ready and now - slot.since > self.init_timeout_s:
            if not self._any_ready:
                raise WorkerStartError(f"worker did not start within {self.init_timeout_s:g} s "
                                       "(is there room for every worker: CPUs, GPUs, memory?)")
            self._lost(slot, f"worker did not start within {self.init_timeout_s:g} s", stop=True)
        elif slot.ready and slot.item is not None and now - slot.since > self.timeout_s:
            item = slot.item
            slot.item = None
            self._retire(slot)
            self._on_result(item.failed(f"episode timed out after {self.timeout_s:g} s (watchdog)",
                                         attempts=self._attempts[item.episode_index]))

    def _report(self, slot: _Slot, result: EpisodeResult, retry: bool = True) -> None:
        """The slot's episode is done; an infrastructure failure (its worker lives on, e.g. with a new suite
        process) is retried on the slot while ``retry`` and retries are left, as a worker's death is."""
        item = slot.item
        if item is None or item.episode_index != result.episode_index:
            return  # not the episode this worker was given: a transport bug must not count twice
        result.attempts = self._attempts.get(result.episode_index, 1)
        slot.item = None
        if not (retry and result.rerun_on_resume and self._retry(slot, item, str(result.error))):
            self._on_result(result)

    def _lost(self, slot: _Slot, reason: str, stop: bool = False) -> None:
        """The slot's worker is gone: retry its episode (bounded) or record it as an error."""
        item, slot.item = slot.item, None
        if stop:
            self._retire(slot)
        else:
            slot.handle = None
        if item is not None and not self._retry(slot, item, reason):
            self._on_result(item.failed(reason, INFRASTRUCTURE, attempts=self._attempts[item.episode_index]))

    def _retry(self, slot: _Slot, item: EpisodePlan, reason: str) -> bool:
        """Put ``item`` back for the slot's next turn (its worker, or the next one), unless it is out of retries."""
        n = self._attempts[item.episode_index]
        if n > self.retries:
            return False
        log.warning("episode %d: %s; retrying (attempt %d of %d)", item.episode_index, reason, n + 1,
                    self.retries + 1)
        position = self._position[item.episode_index]
        self._pending[position] = item
        slot.last = position - 1  # the slot retries it first
        return True

    def _retire(self, slot: _Slot) -> None:
        """Ask the slot's worker to stop; it is killed if still there after ``stop_timeout_s``."""
        self.transport.stop(slot.handle)
        self._retiring.append((slot.handle, time.monotonic() + self.stop_timeout_s))
        slot.handle = None

    def _reap_retiring(self) -> None:
        now, keep = time.monotonic(), []
        for handle, deadline in self._retiring:
            self.transport.events(handle)  # results of a stopped worker no longer count
            if self.transport.ended(handle):
                continue
            if now > deadline:
                self.transport.kill(handle)
                continue
            keep.append((handle, deadline))
        self._retiring = keep

    # Shutdown ---------------------------------------------------------------------------------
    def _shutdown(self, timeout_s: float, stop: _StopFlag | None) -> None:
        """Stop every worker; results that arrive meanwhile are still reported. Kill stragglers."""
        for slot in self._slots:
            if slot.handle is not None:
                self.transport.stop(slot.handle)
        deadline = time.monotonic() + timeout_s
        signals_seen = stop.count if stop is not None else 0
        while True:
            live = [s for s in self._slots if s.handle is not None]
            for slot in live:
                for kind, payload in self.transport.events(slot.handle):
                    if kind == RESULT:
                        self._report(slot, EpisodeResult.from_dict(payload), retry=False)
                if self.transport.ended(slot.handle):
                    slot.handle = None
            self._reap_retiring()
            live = [s for s in self._slots if s.handle is not None]
            again = stop is not None and stop.count > signals_seen  # a second Ctrl-C: no more waiting
            if not (live or self._retiring) or time.monotonic() > deadline or again:
                break
            self.transport.wait([s.handle for s in live] + [h for h, _ in self._retiring], timeout=0.2)
        for slot in self._slots:
            if slot.handle is not None:
                self.transport.kill(slot.handle)
                slot.handle = None
        for handle, _ in self._retiring:
            self.transport.kill(handle)
        self._retiring = []


def exit_reason(code: int | None) -> str:
    """``signal SIGKILL`` or ``exit code 3`` for a process exit status."""
    if code is not None and code < 0:
        try:
            return f"signal {signal.Signals(-code).name}"
        except ValueError:
            return f"signal {-code}"
    return f"exit code {code}"


# Signals ----------------------------------------------------------------------------------------
class _StopFlag:
    signum: int | None = None
    count = 0


@contextmanager
def _stop_signals() -> Iterator[_StopFlag]:
    """While running in the main thread, SIGINT/SIGTERM set a flag the supervisor loop checks."""
    flag = _StopFlag()
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def handler(signum: int, frame: Any) -> None:
        flag.signum = flag.signum or signum
        flag.count += 1

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield flag
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


# Child processes ---------------------------------------------------------------------------------
@contextmanager
def reaping_children(timeout_s: float = 10.0) -> Iterator[None]:
    """Around a program's main: on the way out, end the multiprocessing helper processes started
    inside (resource tracker, fork server) and wait for every child process started inside.

    Children still running after ``timeout_s`` are killed; every one is reaped, so none is left
    to the init process (a zombie where init does not reap). Children that existed before are
    left alone.
    """
    from multiprocessing import forkserver, resource_tracker

    helpers = [h for h in (resource_tracker._resource_tracker, forkserver._forkserver) if _helper_pid(h) is None]
    before = set(_children())
    try:
        yield
    finally:
        for helper in helpers:
            if _helper_pid(helper) is not None:
                with suppress(OSError, ChildProcessError):
                    helper._stop()  # type: ignore[union-attr]
        deadline = time.monotonic() + timeout_s
        done: set[int] = set(before)
        while pids := [p for p in _children() if p not in done]:
            for pid in pids:
                try:
                    if os.waitpid(pid, os.WNOHANG)[0]:
                        done.add(pid)
                    elif time.monotonic() > deadline:
                        os.kill(pid, signal.SIGKILL)
                        os.waitpid(pid, 0)
                        done.add(pid)
                except (ChildProcessError, ProcessLookupError):
                    done.add(pid)  # reaped elsewhere meanwhile
            time.sleep(0.02)


def _helper_pid(helper: Any) -> int | None:
    return getattr(helper, "_pid", None) or getattr(helper, "_forkserver_pid", None)


def _children() -> list[int]:
    """This process's child pids (Linux ``/proc``; empty elsewhere)."""
    pids: list[int] = []
    for task in Path(f"/proc/{os.getpid()}/task").glob("*"):
        try:
            pids.extend(int(p) for p in (task / "children").read_text().split())
        except OSError:
            continue
    return pids
