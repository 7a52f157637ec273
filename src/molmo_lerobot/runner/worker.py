"""Per-worker state and the work item the supervisor hands it: one episode at a time.

The same :class:`EpisodeWorker` runs inside worker processes and Ray actors, so every
transport shares the one rollout loop and gives the same per-episode outcomes. The main
process resolves each episode's task type and horizon once; they travel in the work item.
"""

from __future__ import annotations

import os
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from molmo_lerobot.cpu_threads import cap_threads
from molmo_lerobot.errors import EPISODE, describe, error_kind
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.runner.recorders import EpisodeInfo, RecorderFactory, RecorderGroup
from molmo_lerobot.runner.results import EpisodeResult
from molmo_lerobot.runner.rollout import rollout


@dataclass(frozen=True)
class WorkItem:
    """One episode: its position in the benchmark, its (overridden) spec, its seed, and the
    task type name and horizon (policy steps) resolved for it in the main process."""

    episode_index: int
    spec: dict[str, Any]
    seed: int
    task_type: str
    horizon: int

    def failed(self, error: str, kind: str = EPISODE, **kw: Any) -> EpisodeResult:
        """This episode as an error record (keeping its task type, prompt and horizon)."""
        task, language = self.spec.get("task"), self.spec.get("language")
        return EpisodeResult.failed(
            self.episode_index, self.spec.get("house_index"), task.get("task_cls") if isinstance(task, dict) else None,
            self.seed, error, kind, task_type=self.task_type, horizon=self.horizon,
            prompt=language.get("task_description") if isinstance(language, dict) else "", **kw)


@dataclass
class WorkerJob:
    """Everything a worker needs, picklable (plain data + recorder factories)."""

    policy: dict[str, Any]
    timing: dict[str, float]
    output_dir: str
    benchmark_name: str
    benchmark_sha256: str
    recorders: list[RecorderFactory] = field(default_factory=list)
    #: the run config the worker rebuilds its RunContext from (data paths absolute, plugins.prefer pins)
    config: dict[str, Any] = field(default_factory=dict)
    camera: dict[str, Any] = field(default_factory=dict)  # the run's camera options (camera.system, camera.eval, ...)
    end_on_success: bool = False
    threads: int | None = 1  # CPU threads for torch/BLAS in this worker (None: the libraries' default)


class WorkerStop(BaseException):
    """The supervisor asked this worker to stop while it ran an episode (not an episode error)."""


class EpisodeWorker:
    """Builds the run's context and the policy once, then runs episodes in sequence."""

    def __init__(self, job: WorkerJob, worker_id: str) -> None:
        from molmo_lerobot.context import RunContext
        from molmo_lerobot.runner.policy import make_policy
        from molmo_lerobot.sim.env import Timing

        self.job = job
        self.worker_id = worker_id
        cap_threads(job.threads)
        self.ctx = RunContext.build(job.config)
        self.plugins = self.ctx.plugins
        self.timing = Timing(**job.timing)
        self.policy_name = str(job.policy["name"])
        self.policy = make_policy(self.plugins, job.policy)
        cap_threads(job.threads)  # a policy that imported torch reads the cap now
        self.recorders = RecorderGroup([f.make(worker_id, Path(job.output_dir)) for f in job.recorders])
        self.stopping = False
        self._in_rollout = False

    def request_stop(self) -> None:
        """Stop: abort the running rollout (raises :class:`WorkerStop`), else stop after this episode."""
        self.stopping = True
        if self._in_rollout:
            self._in_rollout = False
            raise WorkerStop

    def run(self, item: WorkItem) -> EpisodeResult:
        """Run one episode; any exception (a policy's ``KeyboardInterrupt`` or ``SystemExit``
        too) becomes this episode's recorded error, with its ``error_kind``. A recorder that fails
        changes only ``output_errors``, never the outcome. :class:`WorkerStop` propagates."""
        from molmo_lerobot.benchmark.task_specs import parse_episode
        from molmo_lerobot.runner.episode import start_episode

        t0 = time.perf_counter()
        raw_task = item.spec.get("task") or {}
        house = item.spec.get("house_index")
        task_cls = raw_task.get("task_cls") if isinstance(raw_task, dict) else None
        result: EpisodeResult
        try:
            spec = parse_episode(item.spec, self.plugins)
            task_type = self.plugins.task_type(item.task_type)
            horizon = item.horizon
            prompt = spec.language.task_description if spec.language else ""
            env, task = start_episode(spec, item.seed, task_type, self.ctx, self.timing, self.job.camera)
            try:
                privileged = self.policy.needs_simulator
                ctx = EpisodeContext(
                    spec=spec, episode_index=item.episode_index, seed=item.seed, prompt=prompt,
                    move_groups=dict(env.move_groups), policy_dt_s=self.timing.policy_dt_ms / 1000.0,
                    env=env if privileged else None, run=self.ctx if privileged else None,
                )
                info = EpisodeInfo(
                    episode_index=item.episode_index, house_index=house, seed=item.seed, prompt=prompt,
                    task_type=task_type.name, fps=1000.0 / self.timing.policy_dt_ms, horizon=horizon,
                    camera_names=list(env.camera_names), img_resolution=tuple(spec.img_resolution),
                    joint_names=dict(env.joint_names), move_groups=dict(env.move_groups),
                    expert=self.policy.needs_simulator,
                    extra={"task_cls": task_cls, "policy": self.policy_name, "robot": spec.robot.robot_name,
                           "object": getattr(spec.task, "pickup_obj_name", None),
                           "benchmark": self.job.benchmark_name, "benchmark_sha256": self.job.benchmark_sha256},
                    catalog=self.ctx.catalog,
                )
                if self.stopping:
                    raise WorkerStop
                self._in_rollout = True
                try:
                    outcome = rollout(env, task, self.policy, ctx, horizon, self.recorders, info, self.policy_name,
                                      end_on_success=self.job.end_on_success)
                finally:
                    self._in_rollout = False
            finally:
                env.close()
            result = EpisodeResult(
                episode_index=item.episode_index, house_index=house, task_cls=task_cls,
                success=outcome.success, success_once=outcome.success_once, steps=outcome.steps,
                seed=item.seed, task_type=task_type.name, prompt=prompt, horizon=horizon,
                extra={"ended_by": outcome.ended_by, "end_on_success": self.job.end_on_success,
                       "success_any_step": outcome.success_any_step, "camera_system": env.camera_system},
            )
        except (Exception, KeyboardInterrupt, SystemExit) as exc:
            result = item.failed(describe(exc), error_kind(exc))
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
