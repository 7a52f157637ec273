"""Per-worker state: the run's context and policy, built once; then one planned episode at a time.

The same :class:`EpisodeWorker` runs inside worker processes and Ray actors, so every
transport shares the one rollout loop and gives the same per-episode outcomes. The main
process plans every episode once (:class:`~molmo_lerobot.runner.plan.EpisodePlan`: overrides,
seed, task type, horizon); the plans are what the supervisor hands the workers.
"""

from __future__ import annotations

import os
import statistics
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot.allocator import bound_arenas, release_free_memory
from molmo_lerobot.benchmark_kinds import run_kind
from molmo_lerobot.cpu_threads import cap_threads
from molmo_lerobot.errors import describe, error_kind
from molmo_lerobot.recording import RecorderFactory, RecorderGroup
from molmo_lerobot.results import EpisodeResult
from molmo_lerobot.runner.placement import nvidia_gpus, place, slot_of
from molmo_lerobot.runner.rollout import rollout

if TYPE_CHECKING:
    from molmo_lerobot.episode_plan import EpisodePlan
    from molmo_lerobot.run_config import RunConfig


@dataclass
class WorkerJob:
    """Everything a worker needs, picklable (plain data + recorder factories)."""

    #: the run config the worker builds its RunContext from (:meth:`RunContext.portable_config`: data paths absolute)
    config: RunConfig
    #: the policy the worker builds: the run's, or a client of the run's policy server
    policy: dict[str, Any]
    output_dir: str
    benchmark_name: str
    benchmark_sha256: str
    #: the render profile's record the run's benchmark names (:attr:`RunContext.render_record`)
    render_record: dict[str, Any] | None = None
    recorders: list[RecorderFactory] = field(default_factory=list)
    #: modules a worker imports before building itself (a fork server imports them once for all)
    preload: list[str] = field(default_factory=list)


class WorkerStop(BaseException):
    """The supervisor asked this worker to stop while it ran an episode (not an episode error)."""


class Startup:
    """Where a worker's start-up went: seconds per phase, in the order they ran.

    The transport times what happens before the worker exists (``launch_s``: process start and
    the imports of unpickling its job; ``imports_s``: the heavy modules a fork server preloads);
    :class:`EpisodeWorker` times ``context_s`` (the run context rebuilt), ``policy_s``,
    ``recorders_s``, and, in its first episode, ``first_scene_s`` (its scene built, compiled
    and reset) and ``renderer_s`` (its OpenGL/EGL contexts created).
    """

    def __init__(self, **phases: float) -> None:
        self.phases: dict[str, float] = dict(phases)

    @contextmanager
    def phase(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.phases[name] = self.phases.get(name, 0.0) + time.perf_counter() - t0

    def report(self) -> dict[str, float]:
        """The phases rounded to ms, with ``ready_s`` (up to the first episode) and ``total_s``."""
        out = {k: round(v, 4) for k, v in self.phases.items()}
        out["ready_s"] = round(sum(v for k, v in self.phases.items() if k not in FIRST_EPISODE_PHASES), 4)
        out["total_s"] = round(sum(self.phases.values()), 4)
        return out


#: Start-up phases measured in the worker's first episode
FIRST_EPISODE_PHASES = ("first_scene_s", "renderer_s")


def startup_summary(by_worker: dict[str, dict[str, float]]) -> dict[str, Any]:
    """``results.json``'s ``startup``: each worker's phases and the median of each phase."""
    phases = list(dict.fromkeys(k for p in by_worker.values() for k in p))
    median = {k: round(statistics.median(p[k] for p in by_worker.values() if k in p), 4) for k in phases}
    return {"workers": dict(sorted(by_worker.items())), "median": median}


class EpisodeWorker:
    """Builds the run's context and the policy once, then runs episodes in sequence."""

    def __init__(self, job: WorkerJob, worker_id: str, startup: Startup | None = None) -> None:
        from molmo_lerobot.context import RunContext
        from molmo_lerobot.policies.factory import make_policy, policy_options

        self.job = job
        self.worker_id = worker_id
        #: where this worker's start-up went; complete after its first episode (:attr:`first_done`)
        self.startup = startup or Startup()
        self.first_done = False
        config = job.config
        bound_arenas()  # a Ray actor's too (a local worker has it from worker_env)
        cap_threads(config.worker_threads)
        with self.startup.phase("context_s"):
            self.run_context = RunContext.build(config, job.render_record)
        self.policy_name = str(job.policy["name"])
        device = policy_options(self.run_context.plugins, job.policy).device  # its model's default if not given
        self.placement = place(slot_of(worker_id), nvidia_gpus(), os.environ, config.executor.model_dump(), device)
        policy_config = dict(job.policy)
        if self.placement.egl_device is not None:
            os.environ["MUJOCO_EGL_DEVICE_ID"] = str(self.placement.egl_device)  # read at the first renderer
        if self.placement.policy_device is not None:
            policy_config["device"] = self.placement.policy_device
        with self.startup.phase("policy_s"):
            self.policy = make_policy(self.run_context.plugins, policy_config)
        #: who asks every episode's observations to carry the task's environment state (``None``: no one)
        self.environment_state_asker = (
            "record_environment_state=true" if config.record_environment_state else
            f"policy {self.policy_name!r}, which reads observation.environment_state"
            if self.policy.needs_environment_state else None)
        cap_threads(config.worker_threads)  # a policy that imported torch reads the cap now
        with self.startup.phase("recorders_s"):
            self.recorders = RecorderGroup([f.make(worker_id, Path(job.output_dir)) for f in job.recorders])
        #: the opener of the run's sessions, from the benchmark's kind (an env suite's keeps its process)
        self.sessions = run_kind(self.run_context.plugins, config).sessions(self.run_context)
        self.stopping = False
        self._in_rollout = False

    def request_stop(self) -> None:
        """Stop: abort the running rollout (raises :class:`WorkerStop`), else stop after this episode."""
        self.stopping = True
        if self._in_rollout:
            self._in_rollout = False
            raise WorkerStop

    def run(self, plan: EpisodePlan) -> EpisodeResult:
        """Run one planned episode; any exception (a policy's ``KeyboardInterrupt`` or ``SystemExit``
        too) becomes this episode's recorded error, with its ``error_kind``. A recorder that fails
        changes only ``output_errors``, never the outcome. :class:`WorkerStop` propagates."""
        t0 = time.perf_counter()
        result: EpisodeResult
        try:
            t_scene = time.perf_counter()
            session = self.sessions.open(plan, self.policy, environment_state=self.environment_state_asker,
                                         end_on_success=self.run_context.config.end_on_success)
            scene_s = time.perf_counter() - t_scene
            try:
                self.recorders.start_episode(session.recorder_info(
                    expert=self.policy.needs_simulator,
                    extra={"policy": self.policy_name, "benchmark": self.job.benchmark_name,
                           "benchmark_sha256": self.job.benchmark_sha256}))
                if self.stopping:
                    raise WorkerStop
                self._in_rollout = True
                try:
                    result = rollout(session, self.policy, self.recorders, self.policy_name)
                finally:
                    self._in_rollout = False
            finally:
                session.close()
            if not self.first_done:
                self.first_done = True
                self.startup.phases.update(first_scene_s=scene_s, renderer_s=session.renderer_setup_s)
        except (Exception, KeyboardInterrupt, SystemExit) as exc:
            result = plan.failed(describe(exc), error_kind(exc))
            if os.environ.get("MOLMO_DEBUG"):
                traceback.print_exc()
        result.duration_s = time.perf_counter() - t0
        self.recorders.end_episode(result)
        release_free_memory()  # what the episode freed (its frames, a house the model cache let go)
        return result

    def close(self) -> None:
        try:
            self.recorders.close()
        finally:
            try:
                self.sessions.close()
            finally:
                self.policy.close()
