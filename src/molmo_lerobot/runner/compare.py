"""Paired comparison of two runs on the episodes they share (``molmo-compare RUN_A RUN_B``).

Two runs are comparable only if they ran the same robots (name and model digest) on the same
benchmark (same content sha256; where it differs, the options that made the episodes differ are
named) under the same trial definition: timing, horizons (run-level and per shared episode),
evaluation options and success-rule thresholds. A difference in any of these is refused
(``allow_different_trials`` compares anyway and lists each difference); other differences
(episode seeds, versions, other config keys) are flagged in the notes. Episodes are paired
by ``episode_index``. An episode that ended in an error counts as a failure, as in
``results.json``, and belongs to its task like any other.

Statistics, per run pair and per task:

* the exact McNemar test: under H0 the discordant pairs split Binomial(b + c, 1/2); the
  two-sided p-value is ``min(1, 2 * P(X <= min(b, c)))``, computed exactly with integers;
* the paired difference of success rates ``B - A`` with a 95 % confidence interval by
  Newcombe's square-and-add method for paired proportions (Newcombe 1998, method 10:
  Wilson intervals for both rates, combined with the continuity-corrected correlation phi).
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from molmo_lerobot.benchmark.schema import known_task_type
from molmo_lerobot.errors import MolmoError
from molmo_lerobot.results import RESULTS_FILE, SUCCESS_LABELS, EpisodeResult, RunFileError, read_run, wilson_ci
from molmo_lerobot.runner.run_directory import robots_named

METRICS = {key: SUCCESS_LABELS[key] for key in ("success", "success_once")}
#: ``results.json`` fields that define the trial an episode is (besides the benchmark).
TRIAL_FIELDS = ("timing", "horizon", "eval_options", "mujoco", "render_profile")
#: ``config`` keys that do not change an episode's trial (who runs it, where its outputs go);
#: a difference in any other key is flagged.
NEUTRAL_CONFIG = frozenset({"policy", "benchmark", "seed", "limit", "episodes", "sample", "workers", "executor",
                            "output_dir", "record", "record_hold_steps", "record_environment_state", "push", "resume",
                            "progress", "hub",
                            "wandb", "video", *TRIAL_FIELDS, "horizons", "custom_object", "camera", "robot"})
Z95 = 1.959963984540054


class CompareError(MolmoError, ValueError):
    """The runs cannot be compared; the message says which run and why."""


@dataclass
class Run:
    """A finished run directory: its ``results.json`` (as written) and its episodes by index."""

    path: Path
    policy: str
    benchmark: dict[str, Any]
    seed: Any
    episodes: dict[int, EpisodeResult]
    results: dict[str, Any]


@dataclass
class PairedStats:
    """Paired 2x2 table of A vs B outcomes and the statistics computed from it."""

    n: int
    both: int
    only_a: int
    only_b: int
    neither: int
    rate_a: float
    rate_b: float
    diff: float  # rate_b - rate_a
    ci95: tuple[float, float]
    p_value: float  # exact McNemar, two-sided


def load_run(path: str | Path) -> Run:
    """A finished run (:func:`~molmo_lerobot.results.read_run`); refuse anything else."""
    try:
        recorded = read_run(path)
    except RunFileError as exc:
        raise CompareError(str(exc)) from None
    summary = recorded.summary
    assert summary is not None  # a finished run has one
    if summary.benchmark is None or not summary.benchmark.sha256:
        raise CompareError(f"{recorded.path / RESULTS_FILE}: field benchmark.sha256 is missing")
    policy = summary.policy or {}
    return Run(recorded.path, str(policy.get("name", "?")), summary.benchmark.model_dump(), summary.seed,
               {r.episode_index: r for r in recorded.episodes}, summary.document())


def mcnemar_exact(only_a: int, only_b: int) -> float:
    """Two-sided exact McNemar p-value for ``only_a`` vs ``only_b`` discordant pairs."""
    if only_a + only_b == 0:
        return 1.0
    from scipy.stats import binomtest

    return float(binomtest(only_a, only_a + only_b, 0.5).pvalue)


def paired_diff_ci(both: int, only_a: int, only_b: int, neither: int, z: float = Z95) -> tuple[float, float]:
    """Newcombe square-and-add CI for ``rate_b - rate_a`` on paired outcomes."""
    n = both + only_a + only_b + neither
    if n == 0:
        return (-1.0, 1.0)
    k_a, k_b = both + only_a, both + only_b
    p_a, p_b = k_a / n, k_b / n
    l_a, u_a = wilson_ci(k_a, n, z)
    l_b, u_b = wilson_ci(k_b, n, z)
    margins = k_a * (n - k_a) * k_b * (n - k_b)
    phi = 0.0
    if margins > 0:
        cross = both * neither - only_a * only_b
        if cross > n / 2:
            phi = (cross - n / 2) / math.sqrt(margins)
        elif cross < 0:
            phi = cross / math.sqrt(margins)
    diff = p_b - p_a
    lower = diff - math.sqrt(max(0.0, (p_b - l_b) ** 2 + (u_a - p_a) ** 2 - 2 * phi * (p_b - l_b) * (u_a - p_a)))
    upper = diff + math.sqrt(max(0.0, (u_b - p_b) ** 2 + (p_a - l_a) ** 2 - 2 * phi * (u_b - p_b) * (p_a - l_a)))
    return (max(-1.0, lower), min(1.0, upper))


def paired_stats(pairs: list[tuple[bool, bool]]) -> PairedStats:
    """Statistics for ``(outcome_a, outcome_b)`` pairs."""
    both = sum(a and b for a, b in pairs)
    only_a = sum(a and not b for a, b in pairs)
    only_b = sum(b and not a for a, b in pairs)
    neither = len(pairs) - both - only_a - only_b
    n = len(pairs)
    rate_a = (both + only_a) / n if n else 0.0
    rate_b = (both + only_b) / n if n else 0.0
    return PairedStats(n, both, only_a, only_b, neither, rate_a, rate_b, rate_b - rate_a,
                       paired_diff_ci(both, only_a, only_b, neither), mcnemar_exact(only_a, only_b))


def _outcome(ep: EpisodeResult, metric: str) -> bool:
    return bool(getattr(ep, metric)) and ep.error is None


_UNSET = object()


def _short(value: Any, limit: int = 200) -> str:
    text = "(unset)" if value is _UNSET else json.dumps(value, sort_keys=True, default=str)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _differences(key: str, a: Any, b: Any) -> list[str]:
    """``"<dotted key> <a> vs <b>"`` for each leaf in which ``a`` and ``b`` differ (nested dicts are walked)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b), key=str)
                for d in _differences(f"{key}.{k}", a.get(k, _UNSET), b.get(k, _UNSET))]
    return [] if a == b else [f"{key} {_short(a)} vs {_short(b)}"]


def trial_differences(run_a: Run, run_b: Run, shared: list[int]) -> tuple[list[str], list[str]]:
    """``(differences, unchecked)``: how the runs' trial definitions differ, and what one run does not record."""
    diffs, unchecked = [], []
    ra, rb = run_a.results, run_b.results
    for key in TRIAL_FIELDS:
        if key not in ra or key not in rb:
            unchecked.append(key)
        else:
            diffs.extend(_differences(key, ra[key], rb[key]))
    ta, tb = ra.get("thresholds") or {}, rb.get("thresholds") or {}
    for task in sorted(set(ta) & set(tb)):  # horizon_steps depends on which episodes ran; checked per episode
        rule_a = {k: v for k, v in ta[task].items() if k != "horizon_steps"}
        rule_b = {k: v for k, v in tb[task].items() if k != "horizon_steps"}
        diffs.extend(_differences(f"thresholds.{task}", rule_a, rule_b))
    horizons = [(i, run_a.episodes[i].horizon, run_b.episodes[i].horizon) for i in shared]
    horizons = [h for h in horizons if h[1] is not None and h[2] is not None and h[1] != h[2]]
    if horizons:
        i, ha, hb = horizons[0]
        diffs.append(f"horizon of {len(horizons)} shared episodes (episode {i}: {ha} vs {hb} steps)")
    return diffs, unchecked


def _flags(run_a: Run, run_b: Run) -> list[str]:
    """Differences that do not change the trial but a reader should know of."""
    notes = []
    va, vb = run_a.results.get("versions") or {}, run_b.results.get("versions") or {}
    changed = [f"{k} {va.get(k)} vs {vb.get(k)}" for k in sorted(set(va) | set(vb)) if va.get(k) != vb.get(k)]
    if changed:
        notes.append("versions differ: " + ", ".join(changed))
    ca, cb = run_a.results.get("config") or {}, run_b.results.get("config") or {}
    other = [k for k in sorted(set(ca) | set(cb)) if k not in NEUTRAL_CONFIG and ca.get(k) != cb.get(k)]
    if other:
        notes.append("config differs: " + ", ".join(d for k in other for d in _differences(k, ca.get(k, _UNSET),
                                                                                           cb.get(k, _UNSET))))
    return notes


def _selection(run: Run) -> str:
    """How ``run`` chose its episodes (``results.json``'s ``selection``, else its ``limit``)."""
    chosen = run.results.get("selection")
    if isinstance(chosen, dict) and chosen.get("kind") == "sample":
        return f"sample={chosen.get('sample')} seed={chosen.get('seed')}"
    if isinstance(chosen, dict) and chosen.get("kind") == "episodes":
        return f"episodes={_short(chosen.get('episodes'), 60)}"
    limit = run.results.get("limit")
    return f"limit={limit}" if limit is not None else "every episode"


def _task(ea: EpisodeResult, eb: EpisodeResult) -> str:
    """The task an episode belongs to, also for records that carry no ``task_type`` (errors of older runs)."""
    for ep in (ea, eb):
        if ep.task_type:
            return ep.task_type
    cls = ea.task_cls or eb.task_cls
    return known_task_type(cls) or str(cls or "unknown")


def _robots(run: Run) -> set[tuple[str, str | None]] | None:
    """The robots ``run`` ran, by name and model digest (``None``: not recorded, a run before they were)."""
    robots = run.results.get("robots")
    return None if robots is None else {(r["name"], r.get("sha256")) for r in robots}


def _episode_options(run_a: Run, run_b: Run) -> list[str]:
    """Where the runs' options that choose a benchmark's episodes differ (``benchmark.*``, ``seed``,
    ``horizon``: an env suite's episodes are made from them), one ``"<key> <a> vs <b>"`` each."""
    ca, cb = run_a.results.get("config") or {}, run_b.results.get("config") or {}
    if not ca or not cb:
        return []
    return [d for key in ("benchmark", "seed", "horizon") for d in _differences(key, ca.get(key, _UNSET),
                                                                                 cb.get(key, _UNSET))]


def compare_runs(run_a: Run, run_b: Run, metric: str = "success",
                 allow_different_trials: bool = False) -> dict[str, Any]:
    """The comparison report (JSON-serializable); raises :class:`CompareError` if not comparable."""
    if metric not in METRICS:
        raise CompareError(f"unknown metric {metric!r} (available: {', '.join(METRICS)})")
    robots_a, robots_b = (_robots(run) for run in (run_a, run_b))
    if robots_a is not None and robots_b is not None and robots_a != robots_b:
        raise CompareError(f"refusing to compare: {run_a.path} ran {robots_named(run_a.results['robots'])} but "
                           f"{run_b.path} ran {robots_named(run_b.results['robots'])}; a paired comparison needs "
                           "the same robot")
    sha_a, sha_b = run_a.benchmark["sha256"], run_b.benchmark["sha256"]
    if sha_a != sha_b:
        causes = _episode_options(run_a, run_b)
        if causes:
            raise CompareError(
                f"refusing to compare: {run_a.path} and {run_b.path} evaluated different episodes of "
                f"{run_a.benchmark.get('name')!r}: {'; '.join(causes)} (benchmark sha256 {sha_a[:12]}… vs "
                f"{sha_b[:12]}…); a paired comparison needs the same episodes")
        raise CompareError(
            f"refusing to compare: {run_a.path} evaluated benchmark {run_a.benchmark.get('name')!r} "
            f"(sha256 {sha_a[:12]}…) but {run_b.path} evaluated {run_b.benchmark.get('name')!r} "
            f"(sha256 {sha_b[:12]}…); a paired comparison needs the same episodes")
    shared = sorted(set(run_a.episodes) & set(run_b.episodes))
    if not shared:
        raise CompareError(f"{run_a.path} and {run_b.path} share no episodes")
    diffs, unchecked = trial_differences(run_a, run_b, shared)
    if diffs and not allow_different_trials:
        raise CompareError(f"refusing to compare: {run_a.path} and {run_b.path} ran different trials: "
                           + "; ".join(diffs) + " (--allow-different-trials compares anyway)")
    by_task: dict[str, list[tuple[bool, bool]]] = defaultdict(list)
    pairs: list[tuple[bool, bool]] = []
    seed_mismatch = 0
    for i in shared:
        ea, eb = run_a.episodes[i], run_b.episodes[i]
        pair = (_outcome(ea, metric), _outcome(eb, metric))
        pairs.append(pair)
        by_task[_task(ea, eb)].append(pair)
        seed_mismatch += ea.seed != eb.seed
    notes = [f"the runs ran different trials (compared anyway): {d}" for d in diffs]
    if unchecked:
        notes.append(f"not recorded by both runs, so not checked: {', '.join(unchecked)}")
    notes.extend(_flags(run_a, run_b))
    if seed_mismatch:
        notes.append(f"{seed_mismatch} shared episodes ran with different episode seeds "
                     f"(run seeds {run_a.seed!r} vs {run_b.seed!r}): pairs share the scene, not the randomization")
    only_in = {"a": sorted(set(run_a.episodes) - set(shared)), "b": sorted(set(run_b.episodes) - set(shared))}
    if only_in["a"] or only_in["b"]:
        notes.append(f"episodes outside the comparison: {len(only_in['a'])} only in A, {len(only_in['b'])} only in B")
        chose = {key: _selection(run) for key, run in (("a", run_a), ("b", run_b))}
        if chose["a"] != chose["b"]:
            notes.append(f"the runs selected their episodes differently (A: {chose['a']}; B: {chose['b']}): "
                         "rerun one with the other's selection to pair them all")
    return {
        "benchmark": {"name": run_a.benchmark.get("name"), "sha256": sha_a},
        "metric": metric,
        "metric_description": METRICS[metric] + "; an episode with an error counts as a failure",
        "runs": {
            key: {"path": str(run.path), "policy": run.policy, "seed": run.seed,
                  "n_errors": sum(run.episodes[i].error is not None for i in shared)}
            for key, run in (("a", run_a), ("b", run_b))
        },
        "n_shared": len(shared),
        "only_in": only_in,
        "overall": asdict(paired_stats(pairs)),
        "per_task": {task: asdict(paired_stats(ps)) for task, ps in sorted(by_task.items())},
        "methods": {
            "difference": "rate_b - rate_a",
            "ci95": "Newcombe square-and-add for paired proportions (1998, method 10, corrected phi)",
            "p_value": "exact McNemar test, two-sided (binomial on discordant pairs)",
        },
        "notes": notes,
    }


def format_report(report: dict[str, Any]) -> str:
    """Human-readable report: header, both runs, overall statistics and a per-task table."""
    o = report["overall"]
    bench = report["benchmark"]
    lines = [f"benchmark {bench['name']} (sha256 {bench['sha256'][:12]}…), {report['n_shared']} shared episodes, "
             f"metric: {report['metric']} ({report['metric_description']})"]
    for key, rate, k in (("a", o["rate_a"], o["both"] + o["only_a"]), ("b", o["rate_b"], o["both"] + o["only_b"])):
        run = report["runs"][key]
        lines.append(f"  {key.upper()}: {run['policy']:<12} {rate:.3f} ({k}/{o['n']})  errors {run['n_errors']}  "
                     f"{run['path']}")
    lo, hi = o["ci95"]
    lines.append(f"  B - A: {o['diff']:+.3f}  95% CI [{lo:+.3f}, {hi:+.3f}] (Newcombe, paired)")
    lines.append(f"  McNemar exact: {o['only_a']} pairs only A succeeded, {o['only_b']} only B; p = {o['p_value']:.4g}")
    lines.append("per task:")
    width = max(4, *(len(t) for t in report["per_task"]))
    lines.append(f"  {'task':<{width}}  {'n':>5}  {'A':>6}  {'B':>6}  {'B-A':>7}  {'95% CI':<17}  {'p':>8}")
    for task, s in report["per_task"].items():
        lo, hi = s["ci95"]
        lines.append(f"  {task:<{width}}  {s['n']:>5}  {s['rate_a']:>6.3f}  {s['rate_b']:>6.3f}  {s['diff']:>+7.3f}  "
                     f"[{lo:+.3f}, {hi:+.3f}]  {s['p_value']:>8.4g}")
    lines.extend(f"note: {n}" for n in report["notes"])
    return "\n".join(lines)
