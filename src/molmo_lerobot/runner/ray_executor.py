"""Ray executor: episodes as work items over simulator actors, supervised like the local pool.

Each actor wraps one :class:`~molmo_lerobot.runner.worker.EpisodeWorker` (plugins and policy
loaded once) and runs one episode per call. The driver hands an episode to an idle actor
and waits on every outstanding call at once:

* a result comes back → reported;
* the actor dies mid-episode (SIGKILL, segfault, OOM, node loss: ``RayActorError``) or its
  call fails outside the episode's own error handling → the actor is replaced and the
  episode retried up to ``retries`` times, then recorded as an error;
* an episode runs past ``timeout_s`` → the actor is killed, the episode recorded as a
  timeout error, and a fresh actor takes its place.

``address=None`` starts a local cluster with ``num_cpus=workers`` (shut down at the end);
``"auto"`` or ``"ray://…"`` joins a running one. A Ray session that is already initialized
in this process is used as is and left running.
"""

from __future__ import annotations

import logging
import os
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from molmo_lerobot.runner.local import WorkerStartError, _failure
from molmo_lerobot.runner.progress import redirect_worker_output
from molmo_lerobot.runner.results import EpisodeResult
from molmo_lerobot.runner.worker import EpisodeWorker, WorkerJob, WorkItem


class SimulatorActor:
    """Body of one Ray actor: an :class:`EpisodeWorker`, or the reason it could not start."""

    def __init__(self, job: WorkerJob, worker_id: str) -> None:
        os.environ.setdefault("MUJOCO_GL", "egl")
        redirect_worker_output(job.output_dir, worker_id)  # library prints go to logs/, not through the bar
        self.worker: EpisodeWorker | None = None
        self.init_error: str | None = None
        try:
            self.worker = EpisodeWorker(job, worker_id)
        except Exception as exc:
            self.init_error = f"{type(exc).__name__}: {exc}"

    def ready(self) -> tuple[str, Any]:
        if self.init_error is not None:
            return "init_error", self.init_error
        return "ready", os.getpid()

    def run(self, item: WorkItem) -> dict[str, Any]:
        assert self.worker is not None
        return self.worker.run(item).to_dict()

    def close(self) -> None:
        if self.worker is not None:
            self.worker.close()


@dataclass
class _Slot:
    index: int
    generation: int
    actor: Any
    ready_ref: Any
    ready: bool = False
    pid: int | None = None
    item: WorkItem | None = None
    ref: Any = None
    started: float = 0.0

    @property
    def worker_id(self) -> str:
        return f"r{self.index}g{self.generation}"


class RayExecutor:
    """Run work items on ``workers`` Ray simulator actors (same contract as ``LocalExecutor``)."""

    def __init__(self, workers: int, address: str | None = None, timeout_s: float = 900.0, retries: int = 1,
                 init_timeout_s: float = 600.0, include_dashboard: bool = False,
                 num_cpus_per_worker: float = 1.0, num_gpus_per_worker: float = 0.0) -> None:
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = workers
        self.address = address
        self.timeout_s = timeout_s
        self.retries = retries
        self.init_timeout_s = init_timeout_s
        self.include_dashboard = include_dashboard
        self.num_cpus_per_worker = num_cpus_per_worker
        self.num_gpus_per_worker = num_gpus_per_worker

    def _connect(self) -> bool:
        """Initialize Ray if needed; returns whether this executor owns (and must end) the session."""
        import ray

        if ray.is_initialized():
            return False
        os.environ.setdefault("MUJOCO_GL", "egl")  # local-cluster workers inherit the driver's environment
        kwargs: dict[str, Any] = dict(include_dashboard=self.include_dashboard, logging_level=logging.WARNING)
        if self.address is None:
            kwargs["num_cpus"] = max(1, int(round(self.workers * self.num_cpus_per_worker)))
        try:
            ray.init(address=self.address, **kwargs)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = "start a local Ray cluster" if self.address is None else f"join the Ray cluster at {self.address!r}"
            raise WorkerStartError(f"could not {where}: {_short(exc)}") from None
        return True

    def _start(self, actor_cls: Any, index: int, generation: int, job: WorkerJob) -> _Slot:
        slot = _Slot(index, generation, None, None)
        slot.actor = actor_cls.options(max_restarts=0, max_task_retries=0,
                                       num_cpus=self.num_cpus_per_worker,
                                       num_gpus=self.num_gpus_per_worker).remote(job, slot.worker_id)
        slot.ready_ref = slot.actor.ready.remote()
        slot.started = time.monotonic()
        return slot

    def run(self, job: WorkerJob, items: list[WorkItem], on_result: Callable[[EpisodeResult], None]) -> None:
        if not items:
            return
        import ray

        owned = self._connect()
        actor_cls = ray.remote(SimulatorActor)
        pending: deque[WorkItem] = deque(items)
        attempts: dict[int, int] = {}
        slots: list[_Slot] = []
        try:
            slots = [self._start(actor_cls, i, 0, job) for i in range(min(self.workers, len(items)))]
            while pending or any(s.item is not None for s in slots):
                for slot in slots:
                    if slot.ready and slot.item is None and pending:
                        slot.item, slot.started = pending.popleft(), time.monotonic()
                        attempts[slot.item.episode_index] = attempts.get(slot.item.episode_index, 0) + 1
                        slot.ref = slot.actor.run.remote(slot.item)
                waiting = [s.ref if s.ready else s.ready_ref for s in slots if s.ref is not None or not s.ready]
                done = set(ray.wait(waiting, num_returns=1, timeout=1.0)[0]) if waiting else set()
                for i, slot in enumerate(slots):
                    slots[i] = self._poll(actor_cls, slot, done, job, pending, attempts, on_result)
        finally:
            self._shutdown(slots)
            if owned:
                ray.shutdown()

    def _poll(self, actor_cls: Any, slot: _Slot, done: set[Any], job: WorkerJob, pending: deque[WorkItem],
              attempts: dict[int, int], on_result: Callable[[EpisodeResult], None]) -> _Slot:
        """Handle whatever happened to one actor; returns the slot (a fresh one if it was replaced)."""
        import ray
        from ray.exceptions import RayActorError, RayError

        now = time.monotonic()
        if not slot.ready:
            if slot.ready_ref in done:
                try:
                    status, payload = ray.get(slot.ready_ref)
                except RayError as exc:
                    raise WorkerStartError(f"simulator actor died while starting: {_short(exc)}") from None
                if status == "init_error":
                    raise WorkerStartError(f"worker could not start: {payload}")
                slot.ready, slot.pid = True, payload
            elif now - slot.started > self.init_timeout_s:
                raise WorkerStartError(f"simulator actor did not start within {self.init_timeout_s:g} s "
                                       "(does the cluster have free CPUs/GPUs for every worker?)")
            return slot
        if slot.item is None:
            return slot
        item = slot.item
        if slot.ref in done:
            try:
                result = EpisodeResult.from_dict(ray.get(slot.ref))
            except RayActorError as exc:
                return self._retry_or_fail(actor_cls, slot, job, pending, attempts, on_result,
                                           f"worker process died during the episode (Ray actor pid {slot.pid}: "
                                           f"{_short(exc)})")
            except RayError as exc:
                return self._retry_or_fail(actor_cls, slot, job, pending, attempts, on_result,
                                           f"worker failed outside the episode: {_short(exc)}")
            result.attempts = attempts.get(result.episode_index, 1)
            on_result(result)
            slot.item = slot.ref = None
            return slot
        if now - slot.started > self.timeout_s:
            ray.kill(slot.actor, no_restart=True)
            on_result(_failure(item, f"episode timed out after {self.timeout_s:g} s (watchdog)",
                               attempts[item.episode_index]))
            return self._start(actor_cls, slot.index, slot.generation + 1, job)
        return slot

    def _retry_or_fail(self, actor_cls: Any, slot: _Slot, job: WorkerJob, pending: deque[WorkItem],
                       attempts: dict[int, int], on_result: Callable[[EpisodeResult], None], reason: str) -> _Slot:
        import ray

        assert slot.item is not None
        item = slot.item
        ray.kill(slot.actor, no_restart=True)
        if attempts[item.episode_index] <= self.retries:
            pending.appendleft(item)
        else:
            on_result(_failure(item, reason, attempts[item.episode_index]))
        return self._start(actor_cls, slot.index, slot.generation + 1, job)

    def _shutdown(self, slots: list[_Slot]) -> None:
        """Let live actors close their recorders, then end them all."""
        import ray
        from ray.exceptions import RayError

        closing = {s.actor.close.remote(): s for s in slots if s.ready and s.item is None}
        if closing:
            try:
                ray.wait(list(closing), num_returns=len(closing), timeout=120)
                for ref in closing:
                    try:
                        ray.get(ref, timeout=0)
                    except RayError:
                        pass
            except RayError:
                pass
        for slot in slots:
            ray.kill(slot.actor, no_restart=True)


def _short(exc: BaseException) -> str:
    """One line for a Ray error: the task's own exception if there is one, else Ray's first line."""
    cause = getattr(exc, "cause", None)
    if isinstance(cause, BaseException):
        text = f"{type(cause).__name__}: {cause}"
    else:
        text = str(exc)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[0] if lines else type(exc).__name__
