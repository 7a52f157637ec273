"""One benchmark episode set up for stepping: overrides applied, seed derived, env built and
reset, task ready. ``molmo-eval``'s workers and the Gymnasium env both start episodes with
:func:`start_episode` and step them with :func:`~molmo_lerobot.runner.rollout.advance`, so
episode ``i`` with run seed ``s`` is the same trial wherever it runs."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.load import Benchmark
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.policies.base import Action
    from molmo_lerobot.sim.env import Env, Timing
    from molmo_lerobot.tasks.base import Task, TaskType


class EpisodeSetupError(ValueError):
    """An episode that cannot be set up; the message names the file, episode and field."""


def load_run_benchmark(benchmark: str | Path, plugins: Plugins):
    """A benchmark by shipped name or by directory/file path; one clear error otherwise."""
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.paths import data_path

    path = Path(str(benchmark)).expanduser()
    if not path.exists():
        shipped = data_path("benchmarks")
        if not (shipped / str(benchmark)).is_dir():
            names = ", ".join(sorted(p.name for p in shipped.iterdir() if p.is_dir()))
            raise EpisodeSetupError(f"unknown benchmark {str(benchmark)!r}: neither a path nor a shipped "
                                    f"benchmark ({names})")
        path = shipped / str(benchmark)
    return load_benchmark(path, plugins)


@dataclass
class Episode:
    """A set-up episode. :meth:`step` is one policy step and returns success in the new state."""

    index: int
    spec: EpisodeSpec
    env: Env
    task: Task
    task_type: TaskType
    horizon: int
    prompt: str
    seed: int

    def step(self, action: Action) -> bool:
        from molmo_lerobot.runner.rollout import advance

        return advance(self.env, self.task, action, "after a step")

    def close(self) -> None:
        self.env.close()


class EpisodeRunner:
    """Sets up episodes of any benchmark with one run's timing, horizon, seed and eval options."""

    def __init__(self, timing: dict[str, float] | None = None, horizon: int | None = None, run_seed: int = 0,
                 eval_options: dict[str, Any] | None = None, horizons: dict[str, float] | None = None) -> None:
        from molmo_lerobot.context import RunContext
        from molmo_lerobot.sim.env import Timing

        self.ctx = RunContext.build(eval_options)
        self.plugins = self.ctx.plugins
        self.timing = Timing(**(timing or {}))
        self.horizon = horizon
        self.horizons = dict(horizons or {})
        self.run_seed = int(run_seed)
        self.eval_options = dict(eval_options or {})

    def horizon_of(self, spec: EpisodeSpec) -> int:
        """Policy steps of ``spec`` under this run's horizon options (as ``molmo-eval`` resolves them)."""
        from molmo_lerobot.runner.rollout import resolve_horizon

        task_type = self.plugins.task_type(spec.task_name)
        return resolve_horizon(self.horizon, spec.task, task_type.default_horizon_sec, self.timing.policy_dt_ms,
                               self.horizons.get(task_type.name))

    def open(self, bench: Benchmark, index: int) -> Episode:
        """Episode ``index`` of ``bench``, reset and ready for its first step."""
        from molmo_lerobot.benchmark.validate import validate_episode
        from molmo_lerobot.molmospaces.preflight import preflight
        from molmo_lerobot.runner.evaluate import episode_seed
        from molmo_lerobot.runner.rollout import check_divergence

        spec = self.plugins.apply_episode_overrides(bench.episodes[index], self.ctx)
        problems = [p for p in validate_episode(spec, self.plugins, self.ctx, index=index,
                                                file=bench.origins[index].file)
                    if not p.warning]  # warnings (not runnable here) are the preflight's
        if problems:
            raise EpisodeSetupError("; ".join(str(p) for p in problems))
        cannot = preflight(bench, self.ctx, [index])
        if cannot:
            raise EpisodeSetupError(cannot)
        seed = episode_seed(self.run_seed, spec.model_dump(mode="json", exclude_unset=False))
        task_type = self.plugins.task_type(spec.task_name)
        horizon = self.horizon_of(spec)
        env, task = start_episode(spec, seed, task_type, self.ctx, self.timing, self.eval_options.get("camera"))
        try:
            check_divergence(env.data, "at the initial state")
            task.setup()
        except Exception:
            env.close()
            raise
        prompt = spec.language.task_description if spec.language else ""
        return Episode(index, spec, env, task, task_type, horizon, prompt, seed)


def start_episode(spec: EpisodeSpec, seed: int, task_type: TaskType, ctx: RunContext, timing: Timing,
                  camera: dict[str, Any] | None) -> tuple[Env, Task]:
    """The episode's environment under the run ``ctx``, reset with ``seed``, and its task (not yet
    set up). The worker's rollout and :meth:`EpisodeRunner.open` both start episodes here."""
    from molmo_lerobot.runner.episode_env import build_env

    env = build_env(spec, timing, ctx, camera)
    try:
        env.reset(seed)
        return env, task_type.create(spec, env)
    except BaseException:
        env.close()
        raise
