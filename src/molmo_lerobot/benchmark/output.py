"""What every benchmark generator writes: numbers rounded for stable JSON, ``benchmark_metadata.json``
and the two files, each written atomically (``molmo-bench generate`` makes the directory appear whole)."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any

from molmo_lerobot.fileio import atomic_write


def rounded(x: float) -> float:
    """``x`` rounded to 5 decimals, for stable, readable JSON."""
    return round(float(x), 5)


def benchmark_metadata(name: str, task: str, description: str, episodes: list[dict[str, Any]], houses: list[int],
                       episodes_per_house: int, seed: int, objects: dict[str, Any], version: int,
                       **extra: Any) -> dict[str, Any]:
    """``benchmark_metadata.json`` of a generated benchmark (``objects`` maps target UIDs to assets,
    ``version`` is the generator's)."""
    categories = Counter(objects[e["task"]["pickup_obj_name"]].category for e in episodes)
    return {
        "name": name,
        "description": description,
        "num_episodes": len(episodes),
        "num_houses": len(houses),
        "task_cls_counts": dict(Counter(e["task"]["task_cls"] for e in episodes)),
        "object_category_counts": dict(sorted(categories.items())),
        **extra,
        "robot_counts": dict(Counter(e["robot"]["robot_name"] for e in episodes)),
        "house_counts": {str(h): episodes_per_house for h in houses},
        "camera_system_class": "standard",
        "generator": {"task": task, "n_houses": len(houses), "episodes_per_house": episodes_per_house, "seed": seed,
                      "version": version},
    }


def write_benchmark(out_dir: str | Path, episodes: list[dict[str, Any]], metadata: dict[str, Any]) -> Path:
    """Write ``benchmark.json`` and ``benchmark_metadata.json`` (each atomically) into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "benchmark_metadata.json", json.dumps(metadata, indent=1) + "\n")
    atomic_write(out / "benchmark.json", json.dumps(episodes, indent=1) + "\n")
    return out
