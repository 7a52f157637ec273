"""``run_evaluation``: benchmark in, honest results out (``results.json``, ``episodes.jsonl``).

It only orchestrates: the run's :class:`~molmo_lerobot.context.RunContext`, one
:class:`~molmo_lerobot.runner.plan.EpisodePlan` per episode (planned here, in the main process),
the executor that runs the plans on workers, the :class:`~molmo_lerobot.runner.run_directory.RunDirectory`
that owns the run's files (durable progress, resume), and the finalizers that run once the run
is scored (datasets, report, W&B). Every attempted episode, even one that errors before it
simulates, is recorded with its task type, prompt, horizon and where that horizon came from
(``horizon_source``), all from its plan.
"""

from __future__ import annotations

import contextlib
import difflib
import platform
import re
import subprocess
import sys
import time
from collections.abc import Collection
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
from omegaconf import DictConfig

from molmo_lerobot.assets.grasps import GraspError
from molmo_lerobot.assets.libraries import AssetError
from molmo_lerobot.benchmark.registry import benchmark_dir
from molmo_lerobot.context import RunContext
from molmo_lerobot.errors import ExportError, InfrastructureError, RunError
from molmo_lerobot.molmospaces.preflight import preflight
from molmo_lerobot.molmospaces.settings import SettingsError
from molmo_lerobot.options import OptionsError
from molmo_lerobot.plugins import PluginError, Plugins
from molmo_lerobot.policies.factory import policy_options
from molmo_lerobot.results import EpisodeResult, RunSummary, summarize
from molmo_lerobot.run_config import RunConfig, episode_work_problem
from molmo_lerobot.runner.finalizers import finalize_run, run_finalizers
from molmo_lerobot.runner.fingerprint import plan_robot, policy_checkpoints, robots_of
from molmo_lerobot.runner.forkserver import ForkServerPool, worker_preload
from molmo_lerobot.runner.memory import available_gb, benchmark_family, memory_warning
from molmo_lerobot.runner.placement import check_devices
from molmo_lerobot.runner.plan import EpisodePlan, EpisodePlanner
from molmo_lerobot.runner.progress import Progress
from molmo_lerobot.runner.run_directory import RunDirectory
from molmo_lerobot.runner.selection import selection_of
from molmo_lerobot.runner.supervisor import RunInterrupted
from molmo_lerobot.runner.worker import WorkerJob, startup_summary
from molmo_lerobot.serving.run_server import ServeError, served_policy
from molmo_lerobot.sim.env import TASK_RULES
from molmo_lerobot.suites.benchmark import (
    SUITE_KEY,
    SuiteBenchmark,
    SuiteBenchmarkError,
    is_suite,
    load_suite_benchmark,
    recording_layout,
    suite_options,
    task_label,
)
from molmo_lerobot.suites.pipe import SuiteError

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.load import Benchmark


@dataclass
class EvalResults:
    """What ``run_evaluation`` returns: the run's summary and every episode."""

    run_summary: RunSummary
    episodes: list[EpisodeResult]
    output_dir: Path

    @property
    def summary(self) -> dict[str, Any]:
        """The ``results.json`` document, as written."""
        return self.run_summary.document()

    @property
    def success_rate(self) -> float | None:
        """Success at the final step; ``None`` when no episode simulated (every one errored)."""
        return self.run_summary.success_rate


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in ("molmo-lerobot", "mujoco", "lerobot", "torch", "numpy", "gymnasium-robotics", "mink"):
        with contextlib.suppress(metadata.PackageNotFoundError):
            out[dist] = metadata.version(dist)
    return out


#: the options that shape a recording: one dataset has one set of them (``run.json``'s ``recording``)
RECORDING_OPTIONS = ("record_environment_state", "record_hold_steps", "record_min_frames", "video")


def code_version() -> dict[str, str | None]:
    """This project's code: its package version and, in a git checkout, the commit (``run.json``'s
    ``code``; a resume refuses other code)."""
    try:
        version: str | None = metadata.version("molmo-lerobot")
    except metadata.PackageNotFoundError:
        version = None
    root = Path(__file__).resolve().parents[3]  # src/molmo_lerobot/runner/ -> the checkout
    commit = None
    if (root / ".git").exists():
        with contextlib.suppress(OSError, subprocess.SubprocessError):
            done = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                  timeout=10, check=False)
            commit = done.stdout.strip() if done.returncode == 0 and done.stdout.strip() else None
    return {"version": version, "commit": commit}


def safe_name(name: str) -> str:
    """``name`` as one harmless path component (no separators, no leading dot)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._-")[:100] or "unnamed"


def resolve_benchmark_path(bench_cfg: dict[str, Any], plugins: Plugins) -> Path:
    if bench_cfg.get("path"):
        return Path(bench_cfg["path"]).expanduser()
    return benchmark_dir(str(bench_cfg["name"]), plugins)


def plugin_option_problems(run: RunContext) -> list[str]:
    """The run options only the installed plugins can check, one line each naming its key: the
    policy's own options (its ``PolicyType.options``), ``camera.system``, ``robot.name``, ``horizons.<task type>``."""
    config = run.config
    try:
        policy_options(run.plugins, config.policy.given())
        out = []
    except OptionsError as exc:
        out = exc.problems
    for key, kind, name in (("camera.system", "camera", config.camera.system), ("robot.name", "robot",
                                                                               config.robot.name)):
        if name is not None:
            try:
                run.plugins.resolve(kind, name)
            except PluginError as exc:
                out.append(f"{key}: {str(exc).splitlines()[0]}")
    task_types = run.plugins.names("task")
    for task in config.horizons:
        if task not in task_types:
            close = difflib.get_close_matches(str(task), task_types, n=1)
            out.append(f"horizons.{task}: no task type {task!r}" + (f"; did you mean horizons.{close[0]}?" if close
                                                                      else f" (task types: {', '.join(task_types)})"))
    return out


def _make_executor(config: RunConfig, fork_servers: ForkServerPool | None = None) -> Any:
    ex = config.executor.model_dump()  # the executor's options are its own (conf/executor/<name>.yaml)
    common: dict[str, Any] = dict(timeout_s=float(config.episode_timeout_s), retries=config.episode_retries)
    if ex["name"] == "local":
        from molmo_lerobot.runner.local import LocalExecutor

        try:
            check_devices(ex)  # read by each worker, checked here
            return LocalExecutor(config.workers, start_method=ex.get("start_method", "forkserver"),
                                 fork_servers=fork_servers, **common)
        except ValueError as exc:
            raise RunError(str(exc)) from None
    if ex["name"] == "ray":
        from molmo_lerobot.runner.ray_executor import RayExecutor

        options: dict[str, Any] = {k: v for k, v in ex.items() if k != "name"}
        try:
            return RayExecutor(config.workers, **options, **common)
        except TypeError as exc:
            raise RunError(f"executor=ray: bad option ({exc}); see conf/executor/ray.yaml") from None
    raise RunError(f"unknown executor {ex['name']!r} (available: local, ray)")


def run_evaluation(config: RunConfig | DictConfig | dict[str, Any], fork_servers: ForkServerPool | None = None,
                   given: Collection[str] | None = None) -> EvalResults:
    """Evaluate ``config.policy`` on ``config.benchmark``; see ``conf/eval.yaml`` for every option.
    ``fork_servers``: where local workers' fork server is borrowed from and given back to (runs in
    one process reusing it), instead of one started and stopped for this run. ``given``: the options
    the command line gave (dotted keys, :func:`~molmo_lerobot.config.given_keys`); a resume takes the
    others from the run (``None``: ``config`` states every option)."""
    from molmo_lerobot.benchmark.load import load_benchmark

    config = RunConfig.of(config)  # validated once (unless given a RunConfig): nonsense stops here
    if config.resume:
        config = _resumed_config(config, given)
    options = config.plain()  # as given: run.json keeps them for a resume
    if config.push and not config.record:
        print("molmo-eval: push=true records the dataset it pushes (record=true)", file=sys.stderr)
    config = config.model_copy(update={"record": config.record or config.push or config.dataset_id is not None})
    try:  # workers build the same context (plugin pins, MolmoSpaces data) from its portable config
        run = RunContext.build(config)
    except (SettingsError, AssetError, GraspError) as exc:
        raise RunError(f"cannot set up MolmoSpaces data: {exc}") from None
    policy_name = config.policy.name
    problems = plugin_option_problems(run)  # unknown or broken policy plugin: fail before any work
    if problems:
        raise RunError("\n".join(problems))
    recorders = run.plugins.recorder_factories(config)  # e.g. a bad hub.repo_id fails here, before any output
    executor = _make_executor(config, fork_servers)
    bench: Benchmark | SuiteBenchmark
    if is_suite(config):  # an env suite's episodes (LIBERO, PushT), played in each worker's suite
        bench = _suite_benchmark(config)
        run = run.with_sleep(bool(config.timing.sleep))  # not our physics: recorded as given, unset false
    else:
        bench = load_benchmark(resolve_benchmark_path(config.benchmark.model_dump(), run.plugins), run.plugins)
        try:  # the render profile it names and whether its episodes sleep travel to the workers
            run = run.for_benchmark(bench)
        except ValueError as exc:  # an unknown profile, a bad MOLMO_SCENE_* override, scenes that disagree on sleep
            raise RunError(str(exc)) from None
    config = config.model_copy(update={"timing": run.config.timing})  # run.json records timing.sleep as decided
    started = datetime.now(UTC)
    run_dir = RunDirectory(Path(config.output_dir or Path("runs") / f"{safe_name(bench.name)}-"
                                f"{safe_name(policy_name)}-{started:%Y%m%d-%H%M%S}"))
    update: dict[str, Any] = {"output_dir": str(run_dir.path)}
    if config.resume and config.limit is None:  # a resume keeps the run's limit unless given a new one
        update["limit"] = run_dir.recorded_limit()
    config = config.model_copy(update=update)
    indices, selection = selection_of(config, bench)  # type: ignore[arg-type]  # episodes, origins, path, name
    if isinstance(bench, SuiteBenchmark):
        plans = {i: _suite_plan(i, bench.suite, bench.episodes[i], config.horizon is not None) for i in indices}
        thresholds: dict[str, Any] = {}
        horizons: dict[str, float] = {}
    else:
        planner = EpisodePlanner(run, bench)
        plans, thresholds = _plan_run(planner, indices)
        horizons = planner.horizons
    run_info = {**_run_info(config, run, bench, horizons, robots_of(run, bench, plans)), "selection": selection}
    done = run_dir.open(run_info, {**options, "output_dir": str(run_dir.path)}, config.resume, recorders)
    outside = sorted(r.episode_index for r in done if r.episode_index not in plans)
    if outside:  # cannot happen with an unchanged benchmark, selection and limit check; never drop them silently
        raise RunError(f"cannot resume {run_dir.path}: it records episodes {outside[:10]} that this run would not "
                       "evaluate")

    if config.executor.name == "local" and (warning := memory_warning(  # before any worker starts
            min(config.workers, len(plans)), benchmark_family(bench.name, config.benchmark.model_dump().get("suite")),
            config.record, available_gb())):
        print(warning, file=sys.stderr)
    t0 = time.perf_counter()
    startups: dict[str, dict[str, float]] = {}  # worker id -> where its start-up went
    results = _run_plans(config, run, bench, plans, {r.episode_index: _complete(r, plans) for r in done}, run_dir,
                         executor, recorders, startups)
    ordered = [results[i] for i in sorted(results)]
    summary = summarize(
        ordered, **run_info, thresholds=thresholds, versions=_versions(), workers=config.workers,
        executor=config.executor.name, output_dir=str(run_dir.path),
        started_at=started.isoformat(), wall_time_s=round(time.perf_counter() - t0, 3), config=config.plain(),
        startup=startup_summary(startups),
    )
    odd = summary.start_warnings
    if odd:
        print(f"molmo-eval: warning: {len(odd)} episode{'s' * (len(odd) != 1)} started oddly (results.json "
              f"start_warnings), e.g. episode {odd[0].episode_index}: {odd[0].warnings[0]}", file=sys.stderr)
    scored = run_dir.write_scored(ordered, summary)  # the score, before any export
    summary = finalize_run(run_dir.path, ordered, summary, recorders, run_finalizers(config))
    run_dir.update_results(summary, scored)
    if summary.export_errors:
        raise ExportError(f"export failed after the run was scored ({'; '.join(summary.export_errors)}); the score "
                          f"stands: {summary.n_success}/{summary.n_episodes} successes in {run_dir.results_file}")
    return EvalResults(run_summary=summary, episodes=ordered, output_dir=run_dir.path)


def _resumed_config(config: RunConfig, given: Collection[str] | None) -> RunConfig:
    """A resume's config: the run's own options (``run.json``) with those the command line gave anew
    (:meth:`RunDirectory.resume_options`); the directory is ``output_dir`` or, with only ``dataset_id``,
    the run that recorded that dataset."""
    out = config.output_dir or (str(_stored_run_dir(config.dataset_id)) if config.dataset_id else None)
    if out is None:
        return config
    keys = None if given is None else {*given, "output_dir"}
    return RunConfig.of(RunDirectory(Path(out)).resume_options({**config.plain(), "output_dir": out}, keys))


def _stored_run_dir(dataset_id: str) -> Path:
    from molmo_lerobot.namespaces import DatasetStore, NamespaceError

    try:
        return DatasetStore().run_dir(dataset_id)
    except NamespaceError as exc:
        raise RunError(f"cannot resume dataset_id={dataset_id}: {exc}; pass output_dir=") from None


def _plan_run(planner: EpisodePlanner, indices: list[int]) -> tuple[dict[int, EpisodePlan], dict[str, Any]]:
    """Every episode of the run planned, the run checked to simulate here (one :class:`RunError`
    line otherwise, before any output or worker), and each task type's thresholds and horizons."""
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
    _warn_default_horizons(bench.path, [plan.described() for plan in plans.values()], timing["policy_dt_ms"])
    return plans, thresholds


def _suite_benchmark(config: RunConfig) -> SuiteBenchmark:
    """The run's env-suite benchmark, its options checked; what suite runs cannot do refused here."""
    if config.record_environment_state:
        raise RunError(f"record_environment_state: env-suite episodes (benchmark={config.benchmark.name}) have no "
                       "environment state; their recording has the suite's own dataset layout")
    if config.robot.name is not None:
        raise RunError(f"robot.name: env-suite episodes (benchmark={config.benchmark.name}) run the robot their "
                       "env builds; leave robot.name out")
    if config.sample is not None:
        raise RunError(f"sample: not available for env-suite benchmarks (benchmark={config.benchmark.name}); "
                       "use limit= or episodes=")
    try:
        if config.record and recording_layout(config) is None:
            raise RunError(f"record=true: env suite {config.benchmark.model_dump().get('suite')!r} "
                           f"(benchmark={config.benchmark.name}) has no recording layout; run without record")
        return load_suite_benchmark(config)
    except (SuiteBenchmarkError, InfrastructureError, SuiteError) as exc:
        raise RunError(str(exc)) from None


def _suite_plan(index: int, suite: str, episode: Any, horizon_from_cli: bool) -> EpisodePlan:
    """Episode ``index`` of env suite ``suite``'s benchmark as a plan: its spec the episode's fields plus
    ``env_suite``, its seed and digest the episode's own, its task the suite's label (``<suite>/task_<id>``)."""
    return EpisodePlan.of(index, {**asdict(episode), SUITE_KEY: suite}, episode.seed, task_label(episode),
                          episode.instruction, episode.horizon, "cli" if horizon_from_cli else "lerobot",
                          episode.digest)


def _run_info(config: RunConfig, run: RunContext, bench: Benchmark | SuiteBenchmark, horizons: dict[str, float],
              robots: list[dict[str, Any]]) -> dict[str, Any]:
    """What the run is (``run.json``; a resume must match it)."""
    prefer, plain = run.plugins.prefer, config.plain()
    return {
        "benchmark": {"name": bench.name, "sha256": bench.sha256, "n_episodes": len(bench.episodes),
                      "path": str(bench.path)},
        "robots": robots,
        "policy": plain["policy"], "policy_checkpoint": policy_checkpoints(plain["policy"]), "seed": config.seed,
        "limit": config.limit, "horizon": config.horizon,
        "timing": plain["timing"], "mujoco": mujoco.__version__, "code": code_version(),
        "render_profile": run.render_record,
        "recording": {key: plain[key] for key in RECORDING_OPTIONS} if config.record else None,
        "eval_options": {"horizons": horizons, "custom_object": plain["custom_object"],
                         "camera": plain["camera"], "robot": plain["robot"],
                         "end_on_success": config.end_on_success,
                         # an env suite's options change its frames (image_size) or episodes
                         **({"benchmark": suite_options(config)} if isinstance(bench, SuiteBenchmark) else {}),
                         **({"task_rules": config.task_rules} if config.task_rules != TASK_RULES[0]
                            else {}),  # the default is left out: runs from before the option resume unchanged
                         "molmospaces": run.settings.to_config(),
                         **({"plugins_prefer": prefer} if prefer else {})},  # pinned providers
    }


def _complete(result: EpisodeResult, plans: dict[int, EpisodePlan]) -> EpisodeResult:
    """Fill what the main process knows of every attempted episode (task type, prompt, horizon, robot)."""
    plan = plans[result.episode_index]
    for key, value in plan.described().items():
        if getattr(result, key) is None:
            setattr(result, key, value)
    robot = plan_robot(plan)
    if robot is not None:
        result.extra.setdefault("robot", robot)
    return result


def _run_plans(config: RunConfig, run: RunContext, bench: Benchmark | SuiteBenchmark, plans: dict[int, EpisodePlan],
               results: dict[int, EpisodeResult], run_dir: RunDirectory, executor: Any,
               recorders: list[Any], startups: dict[str, dict[str, float]]) -> dict[int, EpisodeResult]:
    """Record the plans that cannot run and run the others on ``executor``, each result appended to
    ``episodes.jsonl`` as it comes; ``results`` (those done before a resume) gains every episode,
    ``startups`` each worker's start-up breakdown."""
    todo = [p for p in plans.values() if p.error is None and p.episode_index not in results]
    progress = Progress(len(plans), len(results), f"{bench.name} · {config.policy.name}", run_dir.path,
                        enabled=config.progress, heartbeat_s=float(config.progress_interval_s or 30.0))
    progress.success = sum(r.success for r in results.values())
    progress.errors = sum(r.error is not None for r in results.values())
    log = run_dir.episode_log()
    try:
        with progress:
            def record(result: EpisodeResult) -> None:
                log.append(_complete(result, plans))
                results[result.episode_index] = result
                progress.episode_done(result.success, result.error is not None)

            for plan in plans.values():
                if plan.error is not None and plan.episode_index not in results:
                    record(plan.failed(plan.error))
            if todo:
                # policy.serve=true: one local policy server for the run, the workers its clients;
                # executor=ray serves one per node instead (RayExecutor.served_policy)
                serve = getattr(executor, "served_policy", served_policy)
                try:
                    portable = run.portable_config()
                    with serve(portable, config.workers, run_dir.path, threads=config.worker_threads) as worker_policy:
                        factories = recorders + progress.factories()
                        job = WorkerJob(config=portable, policy=worker_policy, output_dir=str(run_dir.path),
                                        benchmark_name=bench.name, benchmark_sha256=bench.sha256,
                                        render_record=run.render_record, recorders=factories,
                                        preload=worker_preload(run, worker_policy, factories))
                        executor.run(job, todo, record, startups.__setitem__)
                except ServeError as exc:
                    raise RunError(str(exc)) from None
                except RunInterrupted as exc:
                    raise RunInterrupted(exc.signum, f"{exc}: {len(results)} of {len(plans)} episodes finished "
                                         f"and kept in {run_dir.episodes_file}; to continue, rerun with "
                                         f"output_dir={run_dir.path} resume=true") from None
    finally:
        log.close()
    missing = sorted(set(plans) - set(results))
    if missing:
        raise RunError(f"run ended with {len(missing)} episodes unaccounted for: {missing[:10]}")
    return results


def _warn_default_horizons(path: Path, described: list[dict[str, Any]], policy_dt_ms: float) -> None:
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
