"""``run_evaluation``: benchmark in, honest results out (``results.json``, ``episodes.jsonl``).

Progress is durable: each finished episode is appended to ``episodes.jsonl`` (flushed and
fsynced) as it completes, and ``results.json`` is written atomically only when every
episode is accounted for, so an interrupted run never looks complete. ``resume=true`` on the
same ``output_dir`` reruns only the episodes that are missing.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import partial
from importlib import metadata
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from molmo_lerobot.export.report import write_report
from molmo_lerobot.export.wandb_log import log_run
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import get_plugins
from molmo_lerobot.runner.results import EpisodeResult, summarize
from molmo_lerobot.runner.rollout import resolve_horizon
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
    def success_rate(self) -> float:
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


def resolve_benchmark_path(bench_cfg: dict[str, Any]) -> Path:
    if bench_cfg.get("path"):
        return Path(bench_cfg["path"]).expanduser()
    return data_path("benchmarks") / str(bench_cfg["name"])


def _task_horizons(raw: dict[str, Any]) -> dict[str, float]:
    """``horizons.<task>`` in seconds, each a positive number."""
    out: dict[str, float] = {}
    for task, value in raw.items():
        try:
            out[str(task)] = float(value)
        except (TypeError, ValueError):
            out[str(task)] = float("nan")
        if not out[str(task)] > 0:
            raise RunError(f"horizons.{task}: expected a positive number of seconds, got {value!r}")
    return out


def _make_executor(cfg: dict[str, Any]) -> Any:
    ex = cfg.get("executor") or {"name": "local"}
    if int(cfg["workers"]) < 1:
        raise RunError(f"workers must be at least 1, got {cfg['workers']}")
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


def run_evaluation(config: DictConfig | dict[str, Any]) -> EvalResults:
    """Evaluate ``config.policy`` on ``config.benchmark``; see ``conf/eval.yaml`` for every option."""
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.benchmark.validate import validate_benchmark

    cfg = OmegaConf.to_container(config, resolve=True) if isinstance(config, DictConfig) else dict(config)
    if cfg.get("push") and not cfg.get("record"):
        print("molmo-eval: push=true records the dataset it pushes (record=true)", file=sys.stderr)
        cfg["record"] = True
    plugins = get_plugins()
    plugins.set_preferences((cfg.get("plugins") or {}).get("prefer"))  # workers apply the same pins
    policy_name = str(cfg["policy"]["name"])
    plugins.policy(policy_name)  # unknown or broken policy plugin: fail before any work
    recorders = plugins.recorder_factories(cfg)  # e.g. a bad hub.repo_id fails here, before any output
    executor = _make_executor(cfg)
    bench = load_benchmark(resolve_benchmark_path(cfg["benchmark"]))
    problems: dict[int, list[str]] = {}
    for p in validate_benchmark(bench, plugins):
        problems.setdefault(p.episode_index, []).append(f"{p.field}: {p.message}" if p.field else p.message)

    started = datetime.now(UTC)
    out = Path(cfg.get("output_dir") or Path("runs") / f"{bench.name}-{policy_name}-{started:%Y%m%d-%H%M%S}")
    cfg["output_dir"] = str(out)
    limit = cfg.get("limit")
    indices = list(range(len(bench.episodes)))[: int(limit) if limit is not None else None]

    horizons = _task_horizons(cfg.get("horizons") or {})
    items: list[WorkItem] = []
    errors: list[EpisodeResult] = []
    thresholds: dict[str, dict[str, Any]] = {}
    for i in indices:
        try:
            spec = plugins.apply_episode_overrides(bench.episodes[i], cfg)
        except Exception as exc:  # an override that cannot apply to this episode fails it, not the run
            original = bench.episodes[i]
            errors.append(EpisodeResult.failed(i, original.house_index, original.task.task_cls,
                                               episode_seed(cfg["seed"], original.model_dump(mode="json")),
                                               f"episode override failed: {type(exc).__name__}: {exc}"))
            continue
        raw = spec.model_dump(mode="json", exclude_unset=False)
        seed = episode_seed(cfg["seed"], raw)
        if i in problems:
            errors.append(EpisodeResult.failed(i, spec.house_index, spec.task.task_cls, seed,
                                               "invalid episode: " + "; ".join(problems[i])))
            continue
        task_type = plugins.task_type(spec.task_name)
        entry = thresholds.setdefault(task_type.name, {**task_type.thresholds(spec), "horizon_steps": []})
        horizon = resolve_horizon(cfg.get("horizon"), spec.task, task_type.default_horizon_sec,
                                  cfg["timing"]["policy_dt_ms"], horizons.get(task_type.name))
        if horizon not in entry["horizon_steps"]:
            entry["horizon_steps"].append(horizon)
        items.append(WorkItem(i, raw, seed, task_type.name, horizon))

    run_info = {
        "benchmark": {"name": bench.name, "sha256": bench.sha256, "n_episodes": len(bench.episodes),
                      "path": str(bench.path)},
        "policy": cfg["policy"], "seed": cfg["seed"], "limit": limit, "horizon": cfg.get("horizon"),
        "timing": cfg["timing"],
        "eval_options": {"horizons": horizons, "custom_object": cfg.get("custom_object"), "camera": cfg.get("camera"),
                         **({"plugins_prefer": plugins.prefer} if plugins.prefer else {})},  # pinned providers
    }
    done = _prepare_output(out, run_info, bool(cfg.get("resume")))
    results: dict[int, EpisodeResult] = {r.episode_index: r for r in done if r.episode_index in set(indices)}
    episodes_path = out / EPISODES_FILE
    todo = [it for it in items if it.episode_index not in results]
    t0 = time.perf_counter()
    with open(episodes_path, "a") as log, tqdm(total=len(indices), initial=len(results), disable=not cfg.get("progress", True),
                                              desc=f"{bench.name} · {policy_name}", unit="ep", file=sys.stderr) as bar:
        def record(result: EpisodeResult) -> None:
            results[result.episode_index] = result
            log.write(json.dumps(result.to_dict()) + "\n")
            log.flush()
            os.fsync(log.fileno())
            bar.update(1)
            n = len(results)
            bar.set_postfix(success=f"{sum(r.success for r in results.values()) / n:.2f}",
                            errors=sum(r.error is not None for r in results.values()))

        for failed in errors:
            if failed.episode_index not in results:
                record(failed)
        if todo:
            job = WorkerJob(policy=cfg["policy"], timing=cfg["timing"], output_dir=str(out),
                            benchmark_name=bench.name, benchmark_sha256=bench.sha256, recorders=recorders,
                            prefer=plugins.prefer)
            try:
                executor.run(job, todo, record)
            except RunInterrupted as exc:
                raise RunInterrupted(exc.signum, f"{exc}: {len(results)} of {len(indices)} episodes finished and "
                                     f"kept in {episodes_path}; to continue, rerun with output_dir={out} "
                                     "resume=true") from None
    ordered = [results[i] for i in sorted(results)]
    missing = sorted(set(indices) - set(results))
    if missing:
        raise RunError(f"run ended with {len(missing)} episodes unaccounted for: {missing[:10]}")
    atomic_write(episodes_path, "".join(json.dumps(r.to_dict()) + "\n" for r in ordered))
    summary = summarize(
        ordered, **run_info, thresholds=thresholds, versions=_versions(), workers=cfg["workers"],
        executor=(cfg.get("executor") or {}).get("name", "local"), output_dir=str(out),
        started_at=started.isoformat(), wall_time_s=round(time.perf_counter() - t0, 3), config=cfg,
    )
    atomic_write(out / RESULTS_FILE, json.dumps(summary, indent=2) + "\n")  # the score, before any export
    failed = []
    for name, step in [*((f"export {type(f).__name__}", partial(f.finalize, out, ordered, summary)) for f in recorders),
                       ("report", partial(write_report, out, summary, ordered)),
                       ("W&B log", partial(log_run, out, summary, ordered))]:
        try:
            step()
        except Exception as exc:
            failed.append(f"{name}: {type(exc).__name__}: {exc}".splitlines()[0])
    if failed:
        raise ExportError(f"export failed after the run was scored ({'; '.join(failed)}); the score stands: "
                          f"{summary['n_success']}/{summary['n_episodes']} successes in {out / RESULTS_FILE}")
    return EvalResults(summary=summary, episodes=ordered, output_dir=out)


def _prepare_output(out: Path, run_info: dict[str, Any], resume: bool) -> list[EpisodeResult]:
    """Create ``out`` (or reopen it on resume) and return the episodes already done."""
    run_file = out / RUN_FILE
    if out.exists() and any(out.iterdir()):
        if not resume:
            raise RunError(f"output_dir {out} already holds a run; pass resume=true to continue it "
                           "or choose another output_dir")
        if not run_file.exists():
            raise RunError(f"cannot resume: {run_file} is missing")
        previous = json.loads(run_file.read_text())
        current = json.loads(json.dumps(run_info))  # compare as stored (JSON turns int keys into strings)
        for key in ("benchmark", "policy", "seed", "horizon", "timing", "eval_options"):
            if previous.get(key) != current.get(key):
                raise RunError(f"cannot resume {out}: its {key} differs from this run's "
                               f"({previous.get(key)!r} vs {current.get(key)!r})")
        (out / RESULTS_FILE).unlink(missing_ok=True)
        done = _read_episodes(out / EPISODES_FILE)
        atomic_write(out / EPISODES_FILE, "".join(json.dumps(r.to_dict()) + "\n" for r in done))
        return done
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(run_file, json.dumps(run_info, indent=2) + "\n")
    (out / EPISODES_FILE).touch()
    return []


def _read_episodes(path: Path) -> list[EpisodeResult]:
    """Episodes persisted so far; a torn last line (killed mid-write) is ignored."""
    done: dict[int, EpisodeResult] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                r = EpisodeResult.from_dict(json.loads(line))
            except (json.JSONDecodeError, TypeError):
                continue
            done[r.episode_index] = r
    return list(done.values())
