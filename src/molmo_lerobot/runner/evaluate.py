"""``run_evaluation``: benchmark in, honest results out (``results.json``, ``episodes.jsonl``).

Progress is durable: each finished episode is appended to ``episodes.jsonl`` (flushed and
fsynced) as it completes, and ``results.json`` is written atomically only when every
episode is accounted for, so an interrupted run never looks complete. A write that fails
(full disk) is rolled back to the last whole record. ``resume=true`` on the same
``output_dir`` runs the episodes that are missing or incomplete: not recorded, recorded
with an infrastructure error (worker died, full disk, policy server gone), with an output
that was not written, or absent from a recorder's output (the dataset of a killed run).
It never drops a recorded episode (a larger ``limit`` extends the run, a smaller one is
refused).

Every attempted episode, even one that errors before it simulates, is recorded with its task
type, prompt, horizon and where that horizon came from (``horizon_source``), all resolved
here in the main process from the episode's spec.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import re
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import partial
from importlib import metadata
from pathlib import Path
from typing import Any

import mujoco
from omegaconf import DictConfig

from molmo_lerobot.export.report import write_report
from molmo_lerobot.export.wandb_log import log_run
from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.assets.grasps import GraspError
from molmo_lerobot.assets.libraries import AssetError
from molmo_lerobot.context import RunContext
from molmo_lerobot.molmospaces.preflight import preflight
from molmo_lerobot.molmospaces.settings import SettingsError
from molmo_lerobot.paths import data_path
from molmo_lerobot.protocol.run_server import ServeError, served_policy
from molmo_lerobot.runner.fingerprint import policy_checkpoints
from molmo_lerobot.runner.progress import Progress
from molmo_lerobot.runner.results import EpisodeResult, summarize
from molmo_lerobot.runner.rollout import horizon_with_source
from molmo_lerobot.runner.run_config import RunConfig, episode_work_problem
from molmo_lerobot.runner.supervisor import RunInterrupted
from molmo_lerobot.runner.worker import WorkerJob, WorkItem

RUN_FILE = "run.json"
EPISODES_FILE = "episodes.jsonl"
RESULTS_FILE = "results.json"


class RunError(RuntimeError):
    """The run cannot start or continue; the message says why and what to do."""


class ExportError(RunError):
    """The run is scored (``results.json`` written) but an export step after it failed."""


@dataclass
class EvalResults:
    """What ``run_evaluation`` returns: the ``results.json`` document and every episode."""

    summary: dict[str, Any]
    episodes: list[EpisodeResult]
    output_dir: Path

    @property
    def success_rate(self) -> float | None:
        """Success at the final step; ``None`` when no episode simulated (every one errored)."""
        return self.summary["success_rate"]


def episode_seed(run_seed: int, spec: dict[str, Any]) -> int:
    """Seed from the run seed and the episode's identity (its canonical content)."""
    canonical = json.dumps(spec, sort_keys=True, separators=(",", ":"), default=str)
    digest = hashlib.sha256(f"{int(run_seed)}\n{canonical}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in ("molmo-lerobot", "mujoco", "lerobot", "torch", "numpy", "gymnasium-robotics", "mink"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            pass
    return out


def safe_name(name: str) -> str:
    """``name`` as one harmless path component (no separators, no leading dot)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._-")[:100] or "unnamed"


def _write_error(out: Path, what: str, exc: OSError) -> RunError:
    return RunError(f"cannot write {what} in output_dir {out}: {exc.strerror or exc}; finished episodes are kept in "
                    f"{EPISODES_FILE} (fix it, then rerun with resume=true)")


class _EpisodeLog:
    """``episodes.jsonl`` opened for appending whole records: a failed write (full disk) is cut
    back to the last whole record, so the file always parses for resume."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.fd = fileio.open_fd(path, os.O_WRONLY | os.O_APPEND, root=path.parent)

    def append(self, result: EpisodeResult) -> None:
        data = (json.dumps(result.to_dict()) + "\n").encode()
        start = os.fstat(self.fd).st_size
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(self.fd, view):]
            os.fsync(self.fd)
        except OSError as exc:
            try:
                os.ftruncate(self.fd, start)
            except OSError:
                pass
            raise _write_error(self.path.parent, f"episode {result.episode_index}", exc) from None

    def close(self) -> None:
        os.close(self.fd)


def resolve_benchmark_path(bench_cfg: dict[str, Any]) -> Path:
    if bench_cfg.get("path"):
        return Path(bench_cfg["path"]).expanduser()
    return data_path("benchmarks") / str(bench_cfg["name"])


def _make_executor(cfg: dict[str, Any]) -> Any:
    ex = cfg.get("executor") or {"name": "local"}
    common = dict(timeout_s=float(cfg.get("episode_timeout_s", 900)), retries=int(cfg.get("episode_retries", 1)))
    if ex["name"] == "local":
        from molmo_lerobot.runner.local import LocalExecutor

        return LocalExecutor(int(cfg["workers"]), start_method=ex.get("start_method", "spawn"), **common)
    if ex["name"] == "ray":
        from molmo_lerobot.runner.ray_executor import RayExecutor

        options = {k: v for k, v in ex.items() if k != "name"}
        try:
            return RayExecutor(int(cfg["workers"]), **options, **common)
        except TypeError as exc:
            raise RunError(f"executor=ray: bad option ({exc}); see conf/executor/ray.yaml") from None
    raise RunError(f"unknown executor {ex['name']!r} (available: local, ray)")


def run_evaluation(config: RunConfig | DictConfig | dict[str, Any]) -> EvalResults:
    """Evaluate ``config.policy`` on ``config.benchmark``; see ``conf/eval.yaml`` for every option."""
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.benchmark.validate import validate_benchmark

    cfg = RunConfig.of(config).plain()  # validated once (unless given a RunConfig): nonsense stops here
    if cfg.get("push") and not cfg.get("record"):
        print("molmo-eval: push=true records the dataset it pushes (record=true)", file=sys.stderr)
        cfg["record"] = True
    try:  # workers rebuild the same context (plugin pins, MolmoSpaces data) from its portable config
        ctx = RunContext.build(cfg)
    except (SettingsError, AssetError, GraspError) as exc:
        raise RunError(f"cannot set up MolmoSpaces data: {exc}") from None
    plugins = ctx.plugins
    policy_name = str(cfg["policy"]["name"])
    plugins.policy(policy_name)  # unknown or broken policy plugin: fail before any work
    recorders = plugins.recorder_factories(cfg)  # e.g. a bad hub.repo_id fails here, before any output
    executor = _make_executor(cfg)
    bench = load_benchmark(resolve_benchmark_path(cfg["benchmark"]))
    problems: dict[int, list[str]] = {}
    for p in validate_benchmark(bench, plugins, ctx):
        if not p.warning:  # warnings (not runnable here) are the preflight's to report
            problems.setdefault(p.episode_index, []).append(f"{p.field}: {p.message}" if p.field else p.message)

    started = datetime.now(UTC)
    out = Path(cfg.get("output_dir") or Path("runs") / f"{safe_name(bench.name)}-{safe_name(policy_name)}-"
                                                        f"{started:%Y%m%d-%H%M%S}")
    cfg["output_dir"] = str(out)
    limit = cfg.get("limit")
    indices = list(range(len(bench.episodes)))[:limit]
    cannot = preflight(bench, ctx, indices, skip=problems)  # before any output or worker
    if cannot:
        raise RunError(cannot)

    horizons = {str(task): float(sec) for task, sec in (cfg.get("horizons") or {}).items()}
    items: list[WorkItem] = []
    errors: list[EpisodeResult] = []
    described: dict[int, dict[str, Any]] = {}
    thresholds: dict[str, dict[str, Any]] = {}
    too_long: list[tuple[int, str]] = []
    for i in indices:
        original = bench.episodes[i]
        try:
            spec = plugins.apply_episode_overrides(original, ctx)
        except Exception as exc:  # an override that cannot apply to this episode fails it, not the run
            described[i] = _describe(original, plugins, cfg, horizons)
            errors.append(EpisodeResult.failed(i, original.house_index, original.task.task_cls,
                                               episode_seed(cfg["seed"], original.model_dump(mode="json")),
                                               f"episode override failed: {type(exc).__name__}: {exc}"))
            continue
        described[i] = _describe(spec, plugins, cfg, horizons)
        raw = spec.model_dump(mode="json", exclude_unset=False)
        seed = episode_seed(cfg["seed"], raw)
        if i in problems:
            errors.append(EpisodeResult.failed(i, spec.house_index, spec.task.task_cls, seed,
                                               "invalid episode: " + "; ".join(problems[i])))
            continue
        task_type = plugins.task_type(spec.task_name)
        horizon = described[i]["horizon"]
        work = episode_work_problem(horizon, cfg["timing"], f"{bench.where(i)} ({described[i]['horizon_source']})")
        if work:
            too_long.append((i, work))
        entry = thresholds.setdefault(task_type.name, {**task_type.thresholds(spec), "horizon_steps": []})
        if horizon not in entry["horizon_steps"]:
            entry["horizon_steps"].append(horizon)
        items.append(WorkItem(i, raw, seed, task_type.name, horizon))
    if too_long:
        more = f" (and {len(too_long) - 1} more episodes)" if len(too_long) > 1 else ""
        raise RunError(too_long[0][1] + more)
    _warn_default_horizons(bench.path, [described[i] for i in indices], cfg["timing"]["policy_dt_ms"])

    run_info = {
        "benchmark": {"name": bench.name, "sha256": bench.sha256, "n_episodes": len(bench.episodes),
                      "path": str(bench.path)},
        "policy": cfg["policy"], "policy_checkpoint": policy_checkpoints(cfg["policy"]), "seed": cfg["seed"],
        "limit": limit, "horizon": cfg.get("horizon"),
        "timing": cfg["timing"], "mujoco": mujoco.__version__,
        "eval_options": {"horizons": horizons, "custom_object": cfg.get("custom_object"), "camera": cfg.get("camera"),
                         "robot": cfg.get("robot"),
                         "end_on_success": bool(cfg.get("end_on_success", False)),
                         "molmospaces": ctx.settings.to_config(),
                         **({"plugins_prefer": plugins.prefer} if plugins.prefer else {})},  # pinned providers
    }
    done = _prepare_output(out, run_info, bool(cfg.get("resume")), recorders)
    outside = sorted(r.episode_index for r in done if r.episode_index not in described)
    if outside:  # cannot happen with an unchanged benchmark and limit check; never drop them silently
        raise RunError(f"cannot resume {out}: it records episodes {outside[:10]} that this run would not evaluate")

    def complete(result: EpisodeResult) -> EpisodeResult:
        """Fill what the main process knows of every attempted episode (task type, prompt, horizon)."""
        for key, value in described[result.episode_index].items():
            if getattr(result, key) is None:
                setattr(result, key, value)
        return result

    results: dict[int, EpisodeResult] = {r.episode_index: complete(r) for r in done}
    episodes_path = out / EPISODES_FILE
    todo = [it for it in items if it.episode_index not in results]
    t0 = time.perf_counter()
    progress = Progress(len(indices), len(results), f"{bench.name} · {policy_name}", out,
                        enabled=bool(cfg.get("progress", True)),
                        heartbeat_s=float(cfg.get("progress_interval_s") or 30.0))
    progress.success = sum(r.success for r in results.values())
    progress.errors = sum(r.error is not None for r in results.values())
    log = _EpisodeLog(episodes_path)
    try:
        with progress:
            def record(result: EpisodeResult) -> None:
                log.append(complete(result))
                results[result.episode_index] = result
                progress.episode_done(result.success, result.error is not None)

            for failed in errors:
                if failed.episode_index not in results:
                    record(failed)
            if todo:
                try:  # policy.serve=true: one local policy server for the run, the workers its clients
                    with served_policy(ctx.portable_config(), int(cfg["workers"]), out,
                                       threads=cfg.get("worker_threads", 1)) as worker_policy:
                        job = WorkerJob(policy=worker_policy, timing=cfg["timing"], output_dir=str(out),
                                        benchmark_name=bench.name, benchmark_sha256=bench.sha256,
                                        recorders=recorders + progress.factories(), config=ctx.portable_config(),
                                        camera=cfg.get("camera") or {},
                                        end_on_success=bool(cfg.get("end_on_success", False)),
                                        threads=cfg.get("worker_threads", 1))
                        executor.run(job, todo, record)
                except ServeError as exc:
                    raise RunError(str(exc)) from None
                except RunInterrupted as exc:
                    raise RunInterrupted(exc.signum, f"{exc}: {len(results)} of {len(indices)} episodes finished "
                                         f"and kept in {episodes_path}; to continue, rerun with output_dir={out} "
                                         "resume=true") from None
    finally:
        log.close()
    ordered = [results[i] for i in sorted(results)]
    missing = sorted(set(indices) - set(results))
    if missing:
        raise RunError(f"run ended with {len(missing)} episodes unaccounted for: {missing[:10]}")
    summary = summarize(
        ordered, **run_info, thresholds=thresholds, versions=_versions(), workers=cfg["workers"],
        executor=(cfg.get("executor") or {}).get("name", "local"), output_dir=str(out),
        started_at=started.isoformat(), wall_time_s=round(time.perf_counter() - t0, 3), config=cfg,
    )
    scored = json.dumps(summary, indent=2) + "\n"
    try:
        atomic_write(episodes_path, "".join(json.dumps(r.to_dict()) + "\n" for r in ordered), root=out)
        atomic_write(out / RESULTS_FILE, scored, root=out)  # the score, before any export
    except OSError as exc:
        raise _write_error(out, "the run's outputs", exc) from None
    failed = []
    for name, step in [*((f"export {type(f).__name__}", partial(f.finalize, out, ordered, summary)) for f in recorders),
                       ("report", partial(write_report, out, summary, ordered)),
                       ("W&B log", partial(log_run, out, summary, ordered))]:
        try:
            step()
        except Exception as exc:
            failed.append(f"{name}: {type(exc).__name__}: {exc}".splitlines()[0])
    if failed:
        summary["export_errors"] = failed
    if json.dumps(summary, indent=2) + "\n" != scored:  # what the export did (push status, failures); same score
        atomic_write(out / RESULTS_FILE, json.dumps(summary, indent=2) + "\n", root=out)
    if failed:
        raise ExportError(f"export failed after the run was scored ({'; '.join(failed)}); the score stands: "
                          f"{summary['n_success']}/{summary['n_episodes']} successes in {out / RESULTS_FILE}")
    return EvalResults(summary=summary, episodes=ordered, output_dir=out)


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


def _describe(spec: Any, plugins: Any, cfg: dict[str, Any], horizons: dict[str, float]) -> dict[str, Any]:
    """Task type, prompt, horizon and its source of one episode, from its spec alone (never raises)."""
    from molmo_lerobot.benchmark.schema import known_task_type
    from molmo_lerobot.plugins import PluginError

    try:
        task_type = plugins.task_type(spec.task_name)
        name, default_sec = task_type.name, task_type.default_horizon_sec
    except PluginError:  # no plugin for it: the episode is invalid, but it still belongs to its task
        name = known_task_type(spec.task.task_cls, spec.task.task_type) or spec.task_name
        default_sec = None
    horizon = source = None
    if cfg.get("horizon") is not None or horizons.get(name) or spec.task.task_horizon_sec or default_sec:
        horizon, source = horizon_with_source(cfg.get("horizon"), spec.task, default_sec,
                                              cfg["timing"]["policy_dt_ms"], horizons.get(name))
    return {"task_type": name, "prompt": spec.language.task_description, "horizon": horizon,
            "horizon_source": source}


def _prepare_output(out: Path, run_info: dict[str, Any], resume: bool,
                    recorders: list[Any]) -> list[EpisodeResult]:
    """Create ``out`` (or reopen it on resume) and return the episodes already done."""
    run_file = out / RUN_FILE
    if out.exists() and not out.is_dir():
        raise RunError(f"output_dir {out} is a file, not a directory; choose another output_dir")
    try:
        if out.exists() and any(out.iterdir()):
            if not resume:
                raise RunError(f"output_dir {out} already holds a run; pass resume=true to continue it "
                               "or choose another output_dir")
            return _reopen(out, run_info, recorders)
        atomic_write(run_file, json.dumps(run_info, indent=2) + "\n", root=out)  # makes ``out`` too
        os.close(fileio.open_fd(out / EPISODES_FILE, os.O_WRONLY | os.O_CREAT, root=out))
    except OSError as exc:
        raise RunError(f"cannot write output_dir {out}: {exc.strerror or exc}") from None
    return []


def _reopen(out: Path, run_info: dict[str, Any], recorders: list[Any]) -> list[EpisodeResult]:
    """Check that ``out`` holds this same run and return its recorded episodes that stand (resume);
    the others (:func:`_incomplete`) are dropped from ``episodes.jsonl`` and run again."""
    run_file = out / RUN_FILE
    if not run_file.exists():
        raise RunError(f"cannot resume: {run_file} is missing")
    try:
        previous = json.loads(run_file.read_text())
    except (json.JSONDecodeError, RecursionError, UnicodeDecodeError):
        previous = None
    if not isinstance(previous, dict):
        raise RunError(f"cannot resume: {run_file} is not a run description (not a JSON object)")
    current = json.loads(json.dumps(run_info))  # compare as stored (JSON turns int keys into strings)
    for key in ("benchmark", "policy", "policy_checkpoint", "seed", "horizon", "timing", "mujoco", "eval_options"):
        if previous.get(key) != current.get(key):
            raise RunError(f"cannot resume {out}: its {key} differs from this run's "
                           f"({previous.get(key)!r} vs {current.get(key)!r})")
    done = _read_episodes(out / EPISODES_FILE)
    old, new = previous.get("limit"), current["limit"]
    if new is not None and (old is None or new < old):
        recorded, shown = len(done), "null" if old is None else old
        raise RunError(f"cannot resume {out} with limit={new}: it was started with limit={shown} "
                       f"({recorded} episode{'s' * (recorded != 1)} recorded) and a resume never drops recorded "
                       + ("episodes; use limit=null" if old is None else
                          f"episodes; use limit={old} or larger (or limit=null)"))
    rerun = _incomplete(out, done, recorders)
    if rerun:
        print(f"molmo-eval: resume runs {len(rerun)} recorded episodes again ({sorted(rerun)[:10]}"
              f"{' …' if len(rerun) > 10 else ''}): infrastructure errors, outputs not written or not in the "
              "dataset", file=sys.stderr)
        done = [r for r in done if r.episode_index not in rerun]
    fileio.remove(out / RESULTS_FILE, root=out)
    atomic_write(out / EPISODES_FILE, "".join(json.dumps(r.to_dict()) + "\n" for r in done), root=out)
    if new != old:  # a larger limit extends the run
        atomic_write(run_file, json.dumps({**previous, "limit": new}, indent=2) + "\n", root=out)
    return done


def _incomplete(out: Path, done: list[EpisodeResult], recorders: list[Any]) -> set[int]:
    """Recorded episodes a resume runs again: infrastructure failures, episodes with an output not
    written, and those a recorder's output lacks (``RecorderFactory.missing``)."""
    rerun = {r.episode_index for r in done if r.rerun_on_resume or r.output_errors}
    standing = [r for r in done if r.episode_index not in rerun]
    for factory in recorders:
        try:
            rerun |= set(factory.missing(out, standing))
        except Exception as exc:
            raise RunError(f"cannot resume {out}: {type(factory).__name__} cannot tell which episodes its output "
                           f"lacks: {type(exc).__name__}: {exc}".splitlines()[0]) from None
    return rerun


#: ``episodes.jsonl`` fields a record must have, with their JSON types.
_RECORD_TYPES: dict[str, tuple[type, ...]] = {
    "episode_index": (int,), "house_index": (int, type(None)), "task_cls": (str, type(None)), "success": (bool,),
    "success_once": (bool,), "steps": (int,), "seed": (int,), "error": (str, type(None)),
}


def _read_episodes(path: Path) -> list[EpisodeResult]:
    """Episodes persisted so far. A torn last line (killed mid-write) is dropped, its episode
    rerun; any other unreadable record stops the resume with its line number."""
    done: dict[int, EpisodeResult] = {}
    if not path.exists():
        return []
    text = path.read_text(errors="replace")
    lines = text.splitlines()
    for lineno, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            data = json.loads(line)
            why = _record_problem(data)
        except (json.JSONDecodeError, RecursionError) as exc:
            if lineno == len(lines) and not text.endswith("\n"):
                continue  # torn by a kill mid-write
            why = "not valid JSON" if isinstance(exc, json.JSONDecodeError) else "JSON nested too deeply"
        if why:
            raise RunError(f"cannot resume: {path}:{lineno}: corrupt episode record ({why}); "
                           "delete that line to rerun its episode")
        r = EpisodeResult.from_dict(data)
        done[r.episode_index] = r
    return list(done.values())


def _record_problem(data: Any) -> str | None:
    if not isinstance(data, dict):
        return "not a JSON object"
    for key, types in _RECORD_TYPES.items():
        if key not in data:
            return f"field {key!r} is missing"
        value = data[key]
        if not isinstance(value, types) or (isinstance(value, bool) and bool not in types):
            return f"field {key!r} is {json.dumps(value)[:40]}"
    return None
