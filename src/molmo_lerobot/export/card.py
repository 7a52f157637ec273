"""The dataset card (``README.md``): LeRobot's card with the evaluation's score table."""

from __future__ import annotations

from typing import Any

TAGS = ["molmo-lerobot", "evaluation", "rollouts", "mujoco"]


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100.0 * float(x):.1f}%"


def _ci(ci: Any) -> str:
    if ci is None:  # no episode simulated: no interval
        return "n/a"
    lo, hi = (list(ci) + [0.0, 1.0])[:2]
    return f"[{_pct(lo)}, {_pct(hi)}]"


def score_table(summary: dict[str, Any]) -> str:
    """Markdown table: overall and per-task success (at the end and at any step) with Wilson 95% CIs."""
    rows = [("**all**", summary)] + [(f"`{t}`", b) for t, b in sorted((summary.get("per_task") or {}).items())]
    lines = [
        "| task | episodes | success (end) | 95% CI | success (any step) | 95% CI | errors |",
        "|---|---:|---:|---|---:|---|---:|",
    ]
    for name, b in rows:
        lines.append(
            f"| {name} | {b.get('n_episodes', 0)} | {_pct(b.get('success_rate', 0.0))} | {_ci(b.get('ci95', (0, 1)))} "
            f"| {_pct(b.get('success_once_rate', 0.0))} | {_ci(b.get('success_once_ci95', (0, 1)))} "
            f"| {b.get('n_errors', 0)} |"
        )
    return "\n".join(lines)


def description(summary: dict[str, Any], n_recorded: int) -> str:
    """The card's description: what was evaluated, the scores, and where the per-episode records are."""
    bench = summary.get("benchmark") or {}
    policy = summary.get("policy") or {}
    policy_name = policy.get("name", "?") if isinstance(policy, dict) else str(policy)
    sha = str(bench.get("sha256", ""))
    return "\n".join([
        f"Evaluation rollouts of policy `{policy_name}` on benchmark `{bench.get('name', '?')}` "
        f"(sha256 `{sha[:16]}`), recorded with molmo_lerobot.",
        "",
        f"Primary metric: {summary.get('primary_metric', 'success_rate')}. Every attempted episode counts; "
        "errored episodes count as failures and are not stored as dataset episodes.",
        "",
        score_table(summary),
        "",
        f"{n_recorded} of {summary.get('n_episodes', 0)} attempted episodes are stored. "
        "`meta/eval/episodes.jsonl` maps every attempted episode (dataset `episode_index`, or null when "
        "not stored) to its outcome, seed, house, policy and benchmark hash; `results.json` is the run summary.",
    ])


def make_card(meta_info: Any, summary: dict[str, Any], repo_id: str, n_recorded: int) -> Any:
    """A :class:`huggingface_hub.DatasetCard` from LeRobot's template, with the score table."""
    from lerobot.datasets.utils import create_lerobot_dataset_card

    return create_lerobot_dataset_card(**card_kwargs(summary, n_recorded), dataset_info=meta_info, repo_id=repo_id)


def card_kwargs(summary: dict[str, Any], n_recorded: int) -> dict[str, Any]:
    """Keyword arguments for LeRobot's card (also what ``push_to_hub`` forwards to it)."""
    bench = (summary.get("benchmark") or {}).get("name")
    tags = TAGS + ([str(bench)] if bench else [])
    return {"tags": tags, "license": "apache-2.0", "dataset_description": description(summary, n_recorded)}
