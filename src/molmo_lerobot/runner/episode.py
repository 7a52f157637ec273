"""A planned episode set up for stepping: env built and reset, task ready. ``molmo-eval``'s
workers and the Gymnasium env both start episodes with :func:`start_episode` from an
:class:`~molmo_lerobot.runner.plan.EpisodePlan` and step them with
:func:`~molmo_lerobot.runner.rollout.advance`, so episode ``i`` with run seed ``s`` is the same
trial wherever it runs."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from molmo_lerobot.errors import InfrastructureError, MolmoError, describe

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.load import Benchmark
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.policies.base import Action
    from molmo_lerobot.runner.plan import EpisodePlan
    from molmo_lerobot.sim.env import Env
    from molmo_lerobot.tasks.base import Task, TaskType


class EpisodeSetupError(MolmoError, ValueError):
    """An episode that cannot be set up; the message names the file, episode and field."""


def load_run_benchmark(benchmark: str | Path, plugins: Plugins) -> Benchmark:
    """A benchmark by directory/file path or registered name; one clear error otherwise."""
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.benchmark.registry import UnknownBenchmark, find_benchmark

    try:
        return load_benchmark(find_benchmark(benchmark, plugins), plugins)
    except UnknownBenchmark as exc:
        raise EpisodeSetupError(str(exc)) from None


@dataclass
class Episode:
    """A set-up episode. :meth:`step` is one policy step and returns success in the new state."""

    plan: EpisodePlan
    spec: EpisodeSpec
    env: Env
    task: Task
    task_type: TaskType

    @property
    def index(self) -> int:
        return self.plan.episode_index

    @property
    def horizon(self) -> int:
        return self.plan.steps

    @property
    def prompt(self) -> str:
        return self.plan.prompt

    @property
    def seed(self) -> int:
        return self.plan.seed

    def step(self, action: Action) -> bool:
        from molmo_lerobot.runner.rollout import advance

        return advance(self.env, self.task, action, "after a step")

    def close(self) -> None:
        self.env.close()


def open_episode(plan: EpisodePlan, bench: Benchmark, ctx: RunContext) -> Episode:
    """The planned episode of ``bench``, checked to simulate here, reset and ready for its first step."""
    from molmo_lerobot.molmospaces.preflight import preflight
    from molmo_lerobot.runner.rollout import check_divergence

    if plan.error:
        raise EpisodeSetupError(f"{bench.where(plan.episode_index)}: {plan.error}")
    cannot = preflight(bench, ctx, [plan.episode_index])
    if cannot:
        raise EpisodeSetupError(cannot)
    spec = plan.episode(ctx.plugins)
    task_type = ctx.plugins.task_type(plan.task_type)
    env, task = start_episode(spec, plan.seed, task_type, ctx)
    try:
        check_divergence(env.data, "at the initial state")
        task.setup()
    except Exception:
        env.close()
        raise
    return Episode(plan, spec, env, task, task_type)


def install_failure(exc: Exception, spec: EpisodeSpec, ctx: RunContext) -> Exception:
    """``exc``, raised building ``spec``'s scene, as an :class:`InfrastructureError` when the scene
    dataset's installed files are broken now (``resume=true`` reruns the episode once they are
    repaired), else ``exc`` itself."""
    try:
        check = getattr(ctx.plugins.scene_dataset(spec.scene_dataset), "install_problem", None)
        problem = check() if check is not None else None
    except Exception:
        return exc
    if problem is None:
        return exc
    return InfrastructureError(f"{problem} (the scene failed to build: {describe(exc)})")


def start_episode(spec: EpisodeSpec, seed: int, task_type: TaskType, ctx: RunContext) -> tuple[Env, Task]:
    """The episode's environment under the run ``ctx`` (its timing and camera options), reset with
    ``seed``, and its task (not yet set up). The worker's rollout and :func:`open_episode` both
    start episodes here."""
    from molmo_lerobot.runner.episode_env import build_env

    try:
        env = build_env(spec, ctx.timing, ctx, ctx.config.get("camera"))
    except Exception as exc:
        raise install_failure(exc, spec, ctx) from exc
    try:
        env.reset(seed)
        return env, task_type.create(spec, env)
    except BaseException:
        env.close()
        raise
