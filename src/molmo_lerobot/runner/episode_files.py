"""Our own benchmarks as a benchmark kind: episode files (``pick_v1``, a benchmark directory, a MolmoSpaces JSON).

:class:`EpisodeFilesKind` (``episodes``) is the ``trylast`` kind: it claims every name no other kind claims, a
registered benchmark directory (:mod:`molmo_lerobot.benchmark.registry`) or a path, and refuses an unknown one
when it loads it. Its episodes are planned by :class:`~molmo_lerobot.runner.plan.EpisodePlanner` (the run's
overrides, seeds, task types and horizons) and played in :class:`~molmo_lerobot.runner.episode.EpisodeSession`\\ s
built from their scenes.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot.benchmark_kinds import BenchmarkKind, BenchmarkOptions, EpisodeSessions, Listing, RunPlan
from molmo_lerobot.errors import RunError

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.load import Benchmark
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.episode_plan import EpisodePlan
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.policies.base import Policy
    from molmo_lerobot.runner.episode import EpisodeSession
    from molmo_lerobot.runner.plan import EpisodePlanner


class EpisodeFilesKind(BenchmarkKind[BenchmarkOptions]):
    """Benchmarks of episode files (see the module docstring)."""

    name = "episodes"
    options = BenchmarkOptions
    description = "episode files: our benchmark directories and MolmoSpaces' JSON files"

    def benchmarks(self, plugins: Plugins) -> dict[str, Listing]:
        import json

        from molmo_lerobot.benchmark.registry import benchmark_dir, benchmark_names
        from molmo_lerobot.plugins import PluginConflict

        out = {}
        for name in benchmark_names(plugins):
            try:
                path = benchmark_dir(name, plugins)
            except PluginConflict as exc:
                out[name] = Listing("directory", "?", "?", str(exc))
                continue
            meta_file = path / "benchmark_metadata.json"
            meta = json.loads(meta_file.read_text()) if meta_file.is_file() else {}
            out[name] = Listing("directory", str(meta.get("num_episodes", "?")), "per episode", str(path))
        return out

    def claims(self, name: str, path: str | None, plugins: Plugins) -> bool:
        """Every benchmark: an unknown name is refused when loaded, with the registry's did-you-mean."""
        return True

    def load(self, run: RunContext) -> tuple[Benchmark, RunContext]:
        from molmo_lerobot.benchmark.load import load_benchmark

        bench = load_benchmark(benchmark_path(run.config.benchmark.model_dump(), run.plugins), run.plugins)
        try:  # the render profile it names and whether its episodes sleep travel to the workers
            return bench, run.for_benchmark(bench)
        except ValueError as exc:  # an unknown profile, a bad MOLMO_SCENE_* override, scenes that disagree on sleep
            raise RunError(str(exc)) from None

    def plan(self, run: RunContext, bench: Any, indices: list[int]) -> RunPlan:
        from molmo_lerobot.runner.plan import EpisodePlanner

        planner = EpisodePlanner(run, bench)
        plans, thresholds = plan_run(planner, indices)
        return RunPlan(plans, thresholds, planner.horizons)

    def sessions(self, run: RunContext) -> EpisodeFileSessions:
        return EpisodeFileSessions(run)

    def robot(self, plan: EpisodePlan) -> str | None:
        """The spec's ``robot.robot_name`` (after the run's overrides: ``robot.name``)."""
        robot = plan.spec.get("robot")
        name = robot.get("robot_name") if isinstance(robot, dict) else None
        return name if isinstance(name, str) else None

    def robots(self, run: RunContext, plans: dict[int, EpisodePlan]) -> list[dict[str, Any]]:
        """Each robot with its version (the distribution that provides it) and ``sha256`` of its model as built
        for this run (:meth:`~molmo_lerobot.robots.base.RobotType.model_sha256`: MolmoSpaces' model where
        installed differs from the registry-built one)."""
        from molmo_lerobot.plugins import PluginError

        out = []
        for name in sorted({ran for plan in plans.values() if (ran := self.robot(plan)) is not None}):
            try:
                provider = run.plugins.provider("robot", name)
                sha256 = run.plugins.robot(name).configured(run.settings).model_sha256()
            except (PluginError, OSError, ValueError):  # its episodes are recorded as errors, saying why
                continue
            out.append({"name": name, "version": f"{provider.distribution} {provider.version}", "sha256": sha256})
        return out


class EpisodeFileSessions(EpisodeSessions):
    """Each plan's scene built anew (the worker's model cache keeps compiled scenes)."""

    def __init__(self, run: RunContext) -> None:
        self.run = run

    def open(self, plan: EpisodePlan, policy: Policy | None, *, environment_state: str | None = None,
             end_on_success: bool = False) -> EpisodeSession:
        from molmo_lerobot.runner.episode import EpisodeSession

        return EpisodeSession.open(plan, self.run, policy=policy, environment_state=environment_state,
                                   end_on_success=end_on_success)


def benchmark_path(bench_cfg: dict[str, Any], plugins: Plugins) -> Path:
    """``benchmark.path``, else the registered directory of ``benchmark.name``."""
    from molmo_lerobot.benchmark.registry import benchmark_dir

    if bench_cfg.get("path"):
        return Path(bench_cfg["path"]).expanduser()
    return benchmark_dir(str(bench_cfg["name"]), plugins)


def plan_run(planner: EpisodePlanner, indices: list[int]) -> tuple[dict[int, EpisodePlan], dict[str, Any]]:
    """Every episode of the run planned, the run checked to simulate here (one :class:`RunError`
    line otherwise, before any output or worker), and each task type's thresholds and horizons."""
    from molmo_lerobot.molmospaces.preflight import preflight
    from molmo_lerobot.run_config import episode_work_problem

    run, bench = planner.run, planner.bench
    plans = {i: planner.plan(i) for i in indices}
    cannot = preflight(bench, run, indices, skip=[i for i, plan in plans.items() if plan.problems])
    if cannot:
        raise RunError(cannot)
    timing = run.config.timing.model_dump()
    thresholds: dict[str, dict[str, Any]] = {}
    too_long: list[str] = []
    for i, plan in plans.items():
        if plan.error is not None:  # recorded as such, never simulated
            continue
        work = episode_work_problem(plan.steps, timing, f"{bench.where(i)} ({plan.horizon_source})")
        if work:
            too_long.append(work)
        task_type = run.plugins.task_type(plan.task_type)
        entry = thresholds.setdefault(task_type.name,
                                      {**task_type.thresholds(plan.episode(run.plugins)), "horizon_steps": []})
        if plan.horizon not in entry["horizon_steps"]:
            entry["horizon_steps"].append(plan.horizon)
    if too_long:
        more = f" (and {len(too_long) - 1} more episodes)" if len(too_long) > 1 else ""
        raise RunError(too_long[0] + more)
    warn_default_horizons(bench.path, [plan.described() for plan in plans.values()], timing["policy_dt_ms"])
    return plans, thresholds


def warn_default_horizons(path: Path, described: list[dict[str, Any]], policy_dt_ms: float) -> None:
    """One stderr line when episodes run the task types' default horizons (MolmoSpaces' table:
    pick 20 s, pick-and-place 40 s, open/close 30 s): MolmoSpaces refuses a file without
    ``task_horizon_sec`` unless given a horizon; here it runs, says so, and records
    ``horizon_source: default`` per episode (molmo-compare checks per-episode horizons)."""
    used: dict[str, int] = {}
    count = 0
    for d in described:
        if d["horizon_source"] == "default":
            used[d["task_type"]] = d["horizon"]
            count += 1
    if count:
        table = ", ".join(f"{task} {steps * policy_dt_ms / 1000:.3g} s = {steps} steps"
                          for task, steps in sorted(used.items()))
        print(f"molmo-eval: warning: {path}: {count} episode{'s' * (count != 1)} carry no task.task_horizon_sec; "
              f"running MolmoSpaces' default horizons ({table}); MolmoSpaces refuses such a file without a "
              "horizon: pass horizon=<steps> or horizons.<task>=<seconds> to choose", file=sys.stderr)
