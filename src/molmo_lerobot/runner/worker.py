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

from molmo_lerobot.cpu_threads import cap_threads
from molmo_lerobot.errors import describe, error_kind
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.recording import EpisodeInfo, RecorderFactory, RecorderGroup
from molmo_lerobot.results import EpisodeResult
from molmo_lerobot.runner.placement import nvidia_gpus, place, slot_of
from molmo_lerobot.runner.rollout import rollout

if TYPE_CHECKING:
    from molmo_lerobot.runner.plan import EpisodePlan


@dataclass
class WorkerJob:
    """Everything a worker needs, picklable (plain data + recorder factories)."""

    #: the run config the worker rebuilds its RunContext from (data paths absolute, plugins.prefer pins,
    #: timing, camera options, end_on_success, worker_threads)
    config: dict[str, Any]
    #: the policy the worker builds: the run's, or a client of the run's policy server
    policy: dict[str, Any]
    output_dir: str
    benchmark_name: str
    benchmark_sha256: str
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
        from molmo_lerobot.policies.factory import make_policy

        self.job = job
        self.worker_id = worker_id
        #: where this worker's start-up went; complete after its first episode (:attr:`first_done`)
        self.startup = startup or Startup()
        self.first_done = False
        threads = job.config.get("worker_threads", 1)
        cap_threads(threads)
        with self.startup.phase("context_s"):
            self.ctx = RunContext.build(job.config)
        self.timing = self.ctx.timing
        self.end_on_success = bool(job.config.get("end_on_success", False))
        self.record_environment_state = bool(job.config.get("record_environment_state", False))
        self.policy_name = str(job.policy["name"])
        self.placement = place(slot_of(worker_id), nvidia_gpus(), os.environ, job.config.get("executor") or {},
                               job.policy.get("device"))
        policy_config = dict(job.policy)
        if self.placement.egl_device is not None:
            os.environ["MUJOCO_EGL_DEVICE_ID"] = str(self.placement.egl_device)  # read at the first renderer
        if self.placement.policy_device is not None:
            policy_config["device"] = self.placement.policy_device
        with self.startup.phase("policy_s"):
            self.policy = make_policy(self.ctx.plugins, policy_config)
        cap_threads(threads)  # a policy that imported torch reads the cap now
        with self.startup.phase("recorders_s"):
            self.recorders = RecorderGroup([f.make(worker_id, Path(job.output_dir)) for f in job.recorders])
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
        from molmo_lerobot.runner.episode import start_episode

        t0 = time.perf_counter()
        house, task_cls, prompt = plan.house_index, plan.task_cls, plan.prompt
        result: EpisodeResult
        try:
            spec = plan.episode(self.ctx.plugins)
            task_type = self.ctx.plugins.task_type(plan.task_type)
            horizon = plan.steps
            t_scene = time.perf_counter()
            env, task = start_episode(spec, plan.seed, task_type, self.ctx)
            scene_s = time.perf_counter() - t_scene
            try:
                privileged = self.policy.needs_simulator
                env_state = self.record_environment_state or self.policy.needs_environment_state
                if env_state and not task.environment_state_names:
                    who = ("record_environment_state=true" if self.record_environment_state
                           else f"policy {self.policy_name!r}, which reads observation.environment_state")
                    raise ValueError(f"task type {task_type.name!r} defines no environment state (asked for by {who})")
                ctx = EpisodeContext(
                    spec=spec, episode_index=plan.episode_index, seed=plan.seed, prompt=prompt,
                    move_groups=dict(env.move_groups), policy_dt_s=self.timing.policy_dt_ms / 1000.0,
                    env=env if privileged else None, run=self.ctx if privileged else None,
                )
                info = EpisodeInfo(
                    episode_index=plan.episode_index, house_index=house, seed=plan.seed, prompt=prompt,
                    task_type=task_type.name, fps=1000.0 / self.timing.policy_dt_ms, horizon=horizon,
                    camera_names=list(env.camera_names), img_resolution=spec.img_resolution,
                    joint_names=dict(env.joint_names), move_groups=dict(env.move_groups),
                    expert=self.policy.needs_simulator,
                    extra={"task_cls": task_cls, "policy": self.policy_name, "robot": spec.robot.robot_name,
                           "object": getattr(spec.task, "pickup_obj_name", None),
                           "benchmark": self.job.benchmark_name, "benchmark_sha256": self.job.benchmark_sha256},
                    catalog=self.ctx.catalog,
                    environment_state_names=tuple(task.environment_state_names) if env_state else (),
                )
                if self.stopping:
                    raise WorkerStop
                self._in_rollout = True
                try:
                    outcome = rollout(env, task, self.policy, ctx, horizon, self.recorders, info, self.policy_name,
                                      end_on_success=self.end_on_success, environment_state=env_state)
                finally:
                    self._in_rollout = False
            finally:
                env.close()
            if not self.first_done:
                self.first_done = True
                self.startup.phases.update(first_scene_s=scene_s, renderer_s=env.renderer_setup_s)
            result = EpisodeResult(
                episode_index=plan.episode_index, house_index=house, task_cls=task_cls,
                success=outcome.success, success_once=outcome.success_once, steps=outcome.steps,
                seed=plan.seed, task_type=task_type.name, prompt=prompt, horizon=horizon,
                extra={"ended_by": outcome.ended_by, "end_on_success": self.end_on_success,
                       "success_any_step": outcome.success_any_step, "camera_system": env.camera_system,
                       **({"start_warnings": list(odd)} if (odd := getattr(task, "start_warnings", ())) else {}),
                       **({"parity_notes": list(notes)} if (notes := getattr(task, "parity_notes", tuple)()) else {})},
            )
        except (Exception, KeyboardInterrupt, SystemExit) as exc:
            result = plan.failed(describe(exc), error_kind(exc))
            if os.environ.get("MOLMO_DEBUG"):
                traceback.print_exc()
        result.duration_s = time.perf_counter() - t0
        self.recorders.end_episode(result)
        return result

    def close(self) -> None:
        try:
            self.recorders.close()
        finally:
            self.policy.close()
