"""What the throughput tables under tests/perf/ share: a run's wall-clock and start-up-free episode
rates, the policy server's statistics when the run served its policy, and appending rows to
``runs/perf.jsonl``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from molmo_lerobot.serving.run_server import STATS_FILE


def run_rates(res: Any, workers: int, out: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """The row for run ``res`` of ``workers`` workers written to ``out``, and its server stats ({} if unserved).

    Excluding start-up divides the episodes by the time workers spent inside episodes (their summed
    ``duration_s`` over the worker count), so imports, model loads and scene builds are left out."""
    n = len(res.episodes)
    wall = res.summary["wall_time_s"]
    busy = sum(e.duration_s or 0.0 for e in res.episodes) / workers
    stats = json.loads((out / STATS_FILE).read_text()) if (out / STATS_FILE).exists() else {}
    return {"workers": workers, "episodes": n, "wall_s": round(wall, 2), "eps_per_min": round(60 * n / wall, 2),
            "eps_per_min_excl_startup": round(60 * n / busy, 2) if busy else None,
            "errors": res.summary["n_errors"]}, stats


def append_rows(benchmark: str, rows: list[dict[str, Any]], **common: Any) -> None:
    """Append each row to ``runs/perf.jsonl`` as ``{"benchmark": benchmark, **common, **row}``."""
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        for r in rows:
            f.write(json.dumps({"benchmark": benchmark, **common, **r}) + "\n")
