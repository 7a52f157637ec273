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
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import mujoco
from omegaconf import DictConfig

from molmo_lerobot.assets.grasps import GraspError
from molmo_lerobot.assets.libraries import AssetError
from molmo_lerobot.benchmark_kinds import BenchmarkEpisodes, BenchmarkKind, BenchmarkKindError, run_kind
from molmo_lerobot.context import RunContext
from molmo_lerobot.episode_plan import EpisodePlan
from molmo_lerobot.errors import ExportError, InfrastructureError, RunError
from molmo_lerobot.molmospaces.settings import SettingsError
from molmo_lerobot.options import OptionsError
from molmo_lerobot.plugins import PluginError, Plugins
from molmo_lerobot.policies.factory import policy_options
from molmo_lerobot.results import EpisodeResult, RunSummary, summarize
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.finalizers import finalize_run, run_finalizers
from molmo_lerobot.runner.fingerprint import policy_checkpoints
from molmo_lerobot.runner.forkserver import ForkServerPool, worker_preload
from molmo_lerobot.runner.memory import available_gb, benchmark_family, memory_warning
from molmo_lerobot.runner.progress import Progress
from molmo_lerobot.runner.run_directory import RunDirectory
from molmo_lerobot.runner.selection import selection_of
from molmo_lerobot.runner.supervisor import RunInterrupted, Supervisor
from molmo_lerobot.runner.worker import WorkerJob, startup_summary
from molmo_lerobot.serving.run_server import ServeError, served_policy
from molmo_lerobot.sim.env import TASK_RULES


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


def _make_executor(config: RunConfig, plugins: Plugins, fork_servers: ForkServerPool | None = None) -> Supervisor:
    """The run's executor: the plugin of ``executor.name``, its options checked against its model."""
    ex = config.executor.model_dump()
    try:
        kind = plugins.resolve("executor", str(ex["name"]))
        options = kind.validate(ex)
    except (PluginError, ValueError) as exc:
        raise RunError(str(exc)) from None
    try:
        return kind.factory(config.workers, options, float(config.episode_timeout_s), config.episode_retries,
                            fork_servers)
    except ValueError as exc:
        raise RunError(f"executor={kind.name}: {exc}") from None


def run_evaluation(config: RunConfig | DictConfig | dict[str, Any], fork_servers: ForkServerPool | None = None,
                   given: Collection[str] | None = None) -> EvalResults:
    """Evaluate ``config.policy`` on ``config.benchmark``; see ``conf/eval.yaml`` for every option.
    ``fork_servers``: where local workers' fork server is borrowed from and given back to (runs in
    one process reusing it), instead of one started and stopped for this run. ``given``: the options
    the command line gave (dotted keys, :func:`~molmo_lerobot.config.given_keys`); a resume takes the
    others from the run (``None``: ``config`` states every option)."""
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
    kind = _kind(run)  # the benchmark's kind, its options and what it cannot do checked before any work
    # e.g. a bad hub.repo_id fails here, before any output
    recorders = run.plugins.recorder_factories(config, kind.recording_layout(config))
    executor = _make_executor(config, run.plugins, fork_servers)
    try:
        bench, run = kind.load(run)
    except (BenchmarkKindError, InfrastructureError) as exc:
        raise RunError(str(exc)) from None
    config = config.model_copy(update={"timing": run.config.timing})  # run.json records timing.sleep as decided
    started = datetime.now(UTC)
    run_dir = RunDirectory(Path(config.output_dir or Path("runs") / f"{safe_name(bench.name)}-"
                                f"{safe_name(policy_name)}-{started:%Y%m%d-%H%M%S}"))
    update: dict[str, Any] = {"output_dir": str(run_dir.path)}
    if config.resume and config.limit is None:  # a resume keeps the run's limit unless given a new one
        update["limit"] = run_dir.recorded_limit()
    config = config.model_copy(update=update)
    indices, selection = selection_of(config, bench)
    planned = kind.plan(run, bench, indices)
    plans = planned.plans
    run_info = {**_run_info(config, run, kind, bench, planned.horizons, kind.robots(run, plans)),
                "selection": selection}
    done = run_dir.open(run_info, {**options, "output_dir": str(run_dir.path)}, config.resume, recorders)
    outside = sorted(r.episode_index for r in done if r.episode_index not in plans)
    if outside:  # cannot happen with an unchanged benchmark, selection and limit check; never drop them silently
        raise RunError(f"cannot resume {run_dir.path}: it records episodes {outside[:10]} that this run would not "
                       "evaluate")

    if config.executor.name == "local" and (warning := memory_warning(  # before any worker starts
            min(config.workers, len(plans)), benchmark_family(bench.name, kind.name),
            config.record, available_gb())):
        print(warning, file=sys.stderr)
    t0 = time.perf_counter()
    startups: dict[str, dict[str, float]] = {}  # worker id -> where its start-up went
    results = _run_plans(config, run, bench, plans, {r.episode_index: _complete(r, plans, kind) for r in done},
                         run_dir, executor, recorders, startups, kind)
    ordered = [results[i] for i in sorted(results)]
    summary = summarize(
        ordered, **run_info, thresholds=planned.thresholds, versions=_versions(), workers=config.workers,
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


def _kind(run: RunContext) -> BenchmarkKind[Any]:
    """The kind of the run's benchmark (:func:`~molmo_lerobot.benchmark_kinds.run_kind`), the run's options
    checked against it (its ``benchmark.*`` model, what it cannot do); one :class:`RunError` line otherwise."""
    try:
        kind = run_kind(run.plugins, run.config)
        kind.options_of(run.config)
        kind.check_run(run.config)
    except BenchmarkKindError as exc:
        raise RunError(str(exc)) from None
    return kind


def _run_info(config: RunConfig, run: RunContext, kind: BenchmarkKind[Any], bench: BenchmarkEpisodes,
              horizons: dict[str, float], robots: list[dict[str, Any]]) -> dict[str, Any]:
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
                         **kind.run_options(config),  # e.g. an env suite's: they change its frames or episodes
                         **({"task_rules": config.task_rules} if config.task_rules != TASK_RULES[0]
                            else {}),  # the default is left out: runs from before the option resume unchanged
                         "molmospaces": run.settings.to_config(),
                         **({"plugins_prefer": prefer} if prefer else {})},  # pinned providers
    }


def _complete(result: EpisodeResult, plans: dict[int, EpisodePlan], kind: BenchmarkKind[Any]) -> EpisodeResult:
    """Fill what the main process knows of every attempted episode (task type, prompt, horizon, robot)."""
    plan = plans[result.episode_index]
    for key, value in plan.described().items():
        if getattr(result, key) is None:
            setattr(result, key, value)
    robot = kind.robot(plan)
    if robot is not None:
        result.extra.setdefault("robot", robot)
    return result


def _run_plans(config: RunConfig, run: RunContext, bench: BenchmarkEpisodes, plans: dict[int, EpisodePlan],
               results: dict[int, EpisodeResult], run_dir: RunDirectory, executor: Any,
               recorders: list[Any], startups: dict[str, dict[str, float]],
               kind: BenchmarkKind[Any]) -> dict[int, EpisodeResult]:
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
                log.append(_complete(result, plans, kind))
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
