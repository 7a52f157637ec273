"""One episode planned for a run: benchmark episode + run context → a frozen :class:`EpisodePlan`.

Planning checks the benchmark's episode against the run's plugins, applies the run's episode
overrides, derives the episode's seed from the run seed and the content it runs with, and
resolves its task type, prompt and horizon (with where that horizon came from). ``molmo-eval``
plans every episode in the main process and hands the plans to its workers; the Gymnasium env
plans the episodes it opens; so episode ``i`` with run seed ``s`` is the same trial wherever it
runs. An episode that cannot run still gets a plan, saying why (:attr:`EpisodePlan.error`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from molmo_lerobot.episode_plan import EpisodePlan, episode_seed
from molmo_lerobot.hashing import content_sha256

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.load import Benchmark
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.plugins import Plugins


def resolve_horizon(override: int | None, task_spec: Any, default_sec: float, policy_dt_ms: float,
                    task_sec: float | None = None) -> int:
    """Policy steps: CLI override (steps), else the run's per-task horizon (``task_sec``), else
    the episode's ``task_horizon_sec``, else the task type's default."""
    return horizon_with_source(override, task_spec, default_sec, policy_dt_ms, task_sec)[0]


def horizon_with_source(override: int | None, task_spec: Any, default_sec: float | None, policy_dt_ms: float,
                        task_sec: float | None = None) -> tuple[int, str]:
    """:func:`resolve_horizon` and where it came from: ``cli``, ``task_horizons``,
    ``task_horizon_sec`` or ``default``."""
    if override is not None:
        return int(override), "cli"
    episode_sec = getattr(task_spec, "task_horizon_sec", None)
    seconds, source = ((task_sec, "task_horizons") if task_sec else
                       (episode_sec, "task_horizon_sec") if episode_sec else (default_sec, "default"))
    if seconds is None:
        raise ValueError("no horizon: set horizon=, horizons.<task type> or the episode's task_horizon_sec")
    return max(1, round(float(seconds) * 1000.0 / policy_dt_ms)), source


def plan_spec(spec: EpisodeSpec, plugins: Plugins, *, seed: int, horizon: int, index: int = 0) -> EpisodePlan:
    """A plan for ``spec`` outside any benchmark run (a test, a contact sheet), with the given seed
    and horizon: what :meth:`EpisodeSession.start <molmo_lerobot.runner.episode.EpisodeSession.start>`
    starts an episode built by hand from."""
    raw = spec.model_dump(mode="json", exclude_unset=False)
    return EpisodePlan.of(index, raw, int(seed), plugins.task_type(spec.task_name).name, spec.language.task_description,
                       int(horizon), "cli", content_sha256(raw, ensure_ascii=True).hex())


class EpisodePlanner:
    """Plans the episodes of one benchmark under one run (its seed, horizon options and timing)."""

    def __init__(self, run: RunContext, bench: Benchmark) -> None:
        self.run = run
        self.bench = bench
        self.run_seed = run.config.seed
        self.horizon = run.config.horizon
        self.horizons = {str(task): float(sec) for task, sec in run.config.horizons.items()}
        self.policy_dt_ms = run.config.timing.policy_dt_ms

    def plan(self, index: int) -> EpisodePlan:
        """Episode ``index`` of the benchmark, planned (never raises for the episode's own faults)."""
        from molmo_lerobot.benchmark.validate import validate_episode

        original = self.bench.episodes[index]
        problems = tuple(f"{p.field}: {p.message}" if p.field else p.message
                         for p in validate_episode(original, self.run.plugins, self.run, index=index,
                                                   file=self.bench.origins[index].file)
                         if not p.warning)  # warnings (not runnable here) are the preflight's
        try:
            spec = self.run.plugins.apply_episode_overrides(original, self.run)
        except Exception as exc:  # an override that cannot apply to this episode fails it, not the run
            return self._plan(index, original, problems, f"episode override failed: {type(exc).__name__}: {exc}")
        return self._plan(index, spec, problems, "invalid episode: " + "; ".join(problems) if problems else None)

    def _plan(self, index: int, spec: EpisodeSpec, problems: tuple[str, ...], error: str | None) -> EpisodePlan:
        raw = spec.model_dump(mode="json", exclude_unset=False)
        task_type, default_sec = self._task_type(spec)
        horizon = source = None
        if self.horizon is not None or self.horizons.get(task_type) or spec.task.task_horizon_sec or default_sec:
            horizon, source = horizon_with_source(self.horizon, spec.task, default_sec, self.policy_dt_ms,
                                                  self.horizons.get(task_type))
        return EpisodePlan.of(index, raw, episode_seed(self.run_seed, raw), task_type, spec.language.task_description,
                              horizon, source, content_sha256(raw, ensure_ascii=True).hex(), problems, error)

    def _task_type(self, spec: EpisodeSpec) -> tuple[str, float | None]:
        """The task type's name and default horizon (seconds); without a plugin, the known name and none."""
        from molmo_lerobot.benchmark.schema import known_task_type
        from molmo_lerobot.plugins import PluginError

        try:
            task_type = self.run.plugins.task_type(spec.task_name)
        except PluginError:  # no plugin for it: the episode cannot run, but it still belongs to its task
            return known_task_type(spec.task.task_cls, spec.task.task_type) or spec.task_name, None
        return task_type.name, task_type.default_horizon_sec
