"""Episode results and the run summary (``results.json``): honest counts and Wilson CIs.

Every attempted episode counts. An episode that raised, timed out, diverged or whose worker
died is a failure with its ``error`` recorded; it is never dropped from the denominator.
``n_valid`` counts the episodes that simulated (no error). A block in which no episode
simulated measured nothing about the policy: its rates and intervals are ``null`` (not a
0 % score) while every count stays recorded.

An error's ``error_kind`` says whose it is (:mod:`molmo_lerobot.errors`): ``"episode"`` stays
when the run is resumed, ``"infrastructure"`` (worker died, full disk, policy server gone) is
run again. An output that could not be written (a thumbnail, the dataset episode) never
changes the outcome: it is listed in the episode's ``output_errors``.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import asdict, dataclass, field
from typing import Any

from molmo_lerobot.errors import EPISODE, INFRASTRUCTURE


@dataclass
class EpisodeResult:
    """One attempted episode. The first seven fields are the ``episodes.jsonl`` contract."""

    episode_index: int
    house_index: int | None
    task_cls: str | None
    success: bool
    success_once: bool
    steps: int
    seed: int
    error: str | None = None
    task_type: str | None = None
    prompt: str | None = None
    horizon: int | None = None
    horizon_source: str | None = None  # cli | task_horizons | task_horizon_sec | default
    duration_s: float = 0.0
    attempts: int = 1
    error_kind: str | None = None  # with an error: "episode" | "infrastructure" (resume reruns it)
    output_errors: list[str] = field(default_factory=list)  # outputs not written; the outcome stands
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EpisodeResult:
        known = {k: d[k] for k in cls.__dataclass_fields__ if k in d}
        return cls(**known)

    @classmethod
    def failed(cls, episode_index: int, house_index: int | None, task_cls: str | None, seed: int,
               error: str, error_kind: str = EPISODE, **kw: Any) -> EpisodeResult:
        return cls(episode_index, house_index, task_cls, False, False, 0, seed, error, error_kind=error_kind, **kw)

    @property
    def rerun_on_resume(self) -> bool:
        """An infrastructure failure: it says nothing about the policy, so ``resume=true`` reruns it."""
        return self.error is not None and self.error_kind == INFRASTRUCTURE


def wilson_ci(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval (scipy's) for k successes in n trials at ``z`` (``(0, 1)`` when n == 0)."""
    if n == 0:
        return (0.0, 1.0)
    from scipy.stats import binomtest, norm  # lazily: workers import this module, not scipy.stats

    ci = binomtest(k, n).proportion_ci(confidence_level=1 - 2 * norm.sf(z), method="wilson")
    return (float(ci.low), float(ci.high))


def _block(results: list[EpisodeResult]) -> dict[str, Any]:
    n = len(results)
    k = sum(r.success for r in results)
    k_once = sum(r.success_once for r in results)
    n_errors = sum(r.error is not None for r in results)
    scored = n > n_errors  # at least one episode simulated: errors count as failures
    return {
        "success_rate": k / n if scored else None,
        "success_once_rate": k_once / n if scored else None,
        "n_episodes": n,
        "n_valid": n - n_errors,
        "n_success": k,
        "n_success_once": k_once,
        "n_errors": n_errors,
        "ci95": list(wilson_ci(k, n)) if scored else None,
        "success_once_ci95": list(wilson_ci(k_once, n)) if scored else None,
    }


def summarize(results: list[EpisodeResult], **context: Any) -> dict[str, Any]:
    """The ``results.json`` document: overall and per-task blocks plus ``context`` fields."""
    by_task: dict[str, list[EpisodeResult]] = defaultdict(list)
    for r in results:
        by_task[r.task_type or r.task_cls or "unknown"].append(r)
    summary = {"primary_metric": "success_rate (success at the final step)", **_block(results)}
    summary["per_task"] = {t: _block(rs) for t, rs in sorted(by_task.items())}
    summary["errors"] = [
        {"episode_index": r.episode_index, "error": r.error, "error_kind": r.error_kind}
        for r in results if r.error is not None
    ]
    summary["start_warnings"] = [  # episodes MolmoSpaces runs as they are, with an odd start (Task.start_warnings)
        {"episode_index": r.episode_index, "warnings": r.extra["start_warnings"]}
        for r in results if r.extra.get("start_warnings")
    ]
    summary["parity_notes"] = [  # episodes the other task_rules would judge otherwise (Task.parity_notes)
        {"episode_index": r.episode_index, "notes": r.extra["parity_notes"]}
        for r in results if r.extra.get("parity_notes")
    ]
    summary["output_errors"] = [
        {"episode_index": r.episode_index, "errors": r.output_errors} for r in results if r.output_errors
    ]
    summary.update(context)
    return summary


def summary_lines(s: dict[str, Any], max_errors: int = 10) -> list[str]:
    """The run's headline, per-task lines and first errors, for a terminal.

    A run with errors leads with their count; one in which no episode simulated says
    "no episode ran" instead of a score.
    """
    head = f"{s['benchmark']['name']} · {s['policy']['name']}"
    errors = f"{s['n_errors']} of {s['n_episodes']} episodes errored"
    if s["success_rate"] is None:
        lines = [f"no episode ran: {errors} · {head}: no score"]
    else:
        lo, hi = s["ci95"]
        lines = [f"{errors + ' · ' if s['n_errors'] else ''}{head}: success {s['success_rate']:.3f} "
                 f"[{lo:.3f}, {hi:.3f}] ({s['n_success']}/{s['n_episodes']}), "
                 f"success at any step {s['success_once_rate']:.3f}"]
        for task, b in s["per_task"].items():
            rate = "no episode ran" if b["success_rate"] is None else f"{b['success_rate']:.3f}"
            tail = f", {b['n_errors']} errored" if b["n_errors"] else ""
            lines.append(f"  {task}: {rate} ({b['n_success']}/{b['n_episodes']}{tail})")
    lines.extend(f"  episode {e['episode_index']}: {e['error']}" for e in s["errors"][:max_errors])
    if len(s["errors"]) > max_errors:
        lines.append(f"  ... and {len(s['errors']) - max_errors} more errors (results.json)")
    n_infra = sum(e.get("error_kind") == INFRASTRUCTURE for e in s["errors"])
    if n_infra:
        lines.append(f"  {n_infra} of the errors are infrastructure failures (worker, disk, policy server): "
                     "fix the cause and rerun with resume=true to run those episodes again")
    notes = s.get("parity_notes") or []
    if notes:
        lines.append(f"  {len(notes)} episode{'s' * (len(notes) != 1)} judged otherwise by the other task_rules "
                     f"(episode {notes[0]['episode_index']}: {notes[0]['notes'][0]}; all in results.json parity_notes)")
    outputs = s.get("output_errors") or []
    if outputs:
        first = outputs[0]
        lines.append(f"  outputs not written for {len(outputs)} episode{'s' * (len(outputs) != 1)}, outcomes kept "
                     f"(episode {first['episode_index']}: {first['errors'][0]}; all in results.json output_errors)")
    return lines
