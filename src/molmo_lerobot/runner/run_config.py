"""Check a ``molmo-eval`` run config before any work starts: types, ranges and the work it asks for.

:func:`config_problems` lists every problem of the run-level options, one line each, so a
run with nonsense options (``limit=0``, ``horizon=-5``, ``seed=abc``,
``timing.policy_dt_ms=0``) stops before anything is written. :func:`episode_work_problem`
bounds the physics steps one episode may ask for (a horizon of 1e12 seconds or a
0.1 µs physics step would otherwise run until the watchdog).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from molmo_lerobot.benchmark.schema import MAX_TASK_HORIZON_SEC

#: Most policy steps an episode may run (``horizon=``): about two hours at 66 ms per step.
MAX_HORIZON_STEPS = 100_000
#: Most physics steps (``mj_step``) one episode may ask for: horizon x ctrl ticks x substeps.
MAX_PHYSICS_STEPS = 2_000_000
TIMING_KEYS = ("policy_dt_ms", "ctrl_dt_ms", "sim_dt_ms")


class RunConfigError(ValueError):
    """The run config is invalid; ``problems`` holds one line per problem."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def config_problems(cfg: Mapping[str, Any]) -> list[str]:
    """Every problem of the run-level options of ``cfg`` (a resolved ``conf/eval.yaml``), one line each."""
    out: list[str] = []
    workers = cfg.get("workers")
    if not _is_int(workers):
        out.append(f"workers: expected a positive integer, got {workers!r}")
    elif workers < 1:
        out.append(f"workers must be at least 1, got {workers}")
    limit = cfg.get("limit")
    if limit is not None and not (_is_int(limit) and limit >= 1):
        out.append(f"limit: expected a positive integer (or null for every episode), got {limit!r}")
    if not _is_int(cfg.get("seed")):
        out.append(f"seed: expected an integer, got {cfg.get('seed')!r}")
    horizon = cfg.get("horizon")
    if horizon is not None and not (_is_int(horizon) and 1 <= horizon <= MAX_HORIZON_STEPS):
        out.append(f"horizon: expected a whole number of policy steps in 1..{MAX_HORIZON_STEPS} "
                   f"(or null), got {horizon!r}")
    horizons = cfg.get("horizons") or {}
    if not isinstance(horizons, Mapping):
        out.append(f"horizons: expected a mapping of task type to seconds, got {horizons!r}")
        horizons = {}
    for task, value in horizons.items():
        if not (_is_number(value) and 0 < value <= MAX_TASK_HORIZON_SEC):
            out.append(f"horizons.{task}: expected a positive number of seconds, got {value!r} "
                       f"(at most {MAX_TASK_HORIZON_SEC:g})")
    out.extend(_timing_problems(cfg.get("timing")))
    base_size = (cfg.get("robot") or {}).get("base_size", "default")
    if base_size != "default":
        from molmo_lerobot.robots.base import parse_base_size

        try:
            parse_base_size(base_size)
        except ValueError as exc:
            out.append(f"robot.{exc} (or default)")
    from molmo_lerobot.cameras.options import camera_option_problems

    out.extend(camera_option_problems(cfg.get("camera")))
    timeout = cfg.get("episode_timeout_s", 900)
    if not (_is_number(timeout) and timeout > 0):
        out.append(f"episode_timeout_s: expected a positive number of seconds, got {timeout!r}")
    threads = cfg.get("worker_threads", 1)
    if threads is not None and not (_is_int(threads) and threads >= 1):
        out.append(f"worker_threads: expected a positive integer (or null for the libraries' default), got {threads!r}")
    retries = cfg.get("episode_retries", 1)
    if not (_is_int(retries) and retries >= 0):
        out.append(f"episode_retries: expected a non-negative integer, got {retries!r}")
    for key in ("resume", "record", "push", "progress"):
        if key in cfg and not isinstance(cfg[key], bool):
            out.append(f"{key}: expected true or false, got {cfg[key]!r}")
    if cfg.get("output_dir") is not None and not isinstance(cfg["output_dir"], str):
        out.append(f"output_dir: expected a path, got {cfg['output_dir']!r}")
    if not out and horizon is not None:
        problem = episode_work_problem(horizon, cfg["timing"], "horizon")
        if problem:
            out.append(problem)
    return out


def _timing_problems(timing: Any) -> list[str]:
    if not isinstance(timing, Mapping):
        return [f"timing: expected a mapping with {', '.join(TIMING_KEYS)}, got {timing!r}"]
    out = [f"timing.{key}: expected a positive number of milliseconds, got {timing.get(key)!r}"
           for key in TIMING_KEYS if not (_is_number(timing.get(key)) and timing[key] > 0)]
    known = (*TIMING_KEYS, "control", "sleep")
    unknown = sorted(set(timing) - set(known))
    if unknown:
        out.append(f"timing: unknown keys {unknown} (known: {', '.join(known)})")
    if not out:
        from molmo_lerobot.sim.env import Timing

        try:
            Timing(**timing)
        except ValueError as exc:
            out.append(str(exc))
    return out


def physics_steps(horizon: int, timing: Mapping[str, float]) -> int:
    """``mj_step`` calls an episode of ``horizon`` policy steps makes under ``timing``."""
    per_policy_step = round(timing["policy_dt_ms"] / timing["ctrl_dt_ms"]) * round(timing["ctrl_dt_ms"] / timing["sim_dt_ms"])
    return horizon * per_policy_step


def episode_work_problem(horizon: int, timing: Mapping[str, float], what: str) -> str | None:
    """Why ``horizon`` policy steps under ``timing`` is too much work for one episode, or ``None``."""
    steps = physics_steps(horizon, timing)
    if horizon <= MAX_HORIZON_STEPS and steps <= MAX_PHYSICS_STEPS:
        return None
    return (f"{what}: {horizon:,} policy steps x {steps // horizon:,} physics steps each = {steps:,} physics steps, "
            f"over the limit of {MAX_PHYSICS_STEPS:,} per episode (at most {MAX_HORIZON_STEPS:,} policy steps); "
            "lower the horizon (horizon=, horizons.<task>=, task_horizon_sec) or raise timing.sim_dt_ms")


def check_run_config(cfg: Mapping[str, Any]) -> None:
    """Raise :class:`RunConfigError` listing every problem of ``cfg``; return if it can run."""
    problems = config_problems(cfg)
    if problems:
        raise RunConfigError(problems)
