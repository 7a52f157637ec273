"""The scripted expert on franka_droid benchmarks with the published arm and with the FR3 arm.

``python scripts/compare_fr3_arm.py OUT_DIR [--limit N] [--workers W] [BENCHMARK ...]`` runs
``molmo-eval policy=scripted`` (seed 0, the run defaults) on the first N episodes of each benchmark
twice: as published (``franka_droid``) and with every episode's robot renamed ``franka_droid_fr3``
(a copy of the benchmark under OUT_DIR; the published file is only read). It prints a Markdown table
of the per-episode outcomes (docs/parity.md, "The FR3 arm"). A benchmark whose two runs both finished
is not run again; an interrupted run, or one asked for a larger N, resumes (``resume=true``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ["pick_v2", "pick_and_place_v2", "next_to_v2", "color_v2", "open_v2", "close_v2"]
ARMS = {"franka_droid": "panda", "franka_droid_fr3": "fr3"}


def benchmark_copy(name: str, robot: str, out: Path) -> Path:
    """``benchmarks/<name>`` with every episode's robot set to ``robot``, written under ``out``."""
    episodes = json.loads((ROOT / "benchmarks" / name / "benchmark.json").read_text())
    for i, episode in enumerate(episodes):
        if episode["robot"]["robot_name"] != "franka_droid":
            sys.exit(f"{name}: episode {i} robot.robot_name is {episode['robot']['robot_name']!r}, not franka_droid")
        episode["robot"]["robot_name"] = robot
    path = out / "benchmarks" / f"{name}_{ARMS[robot]}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(episodes))
    return path


def outcomes(run_dir: Path, limit: int) -> list[str] | None:
    """Per-episode outcome (``1`` success, ``0`` failure, ``E`` error) of a finished run, else None."""
    path = run_dir / "episodes.jsonl"
    if not path.is_file():
        return None
    rows = sorted((json.loads(line) for line in path.read_text().splitlines() if line.strip()),
                  key=lambda row: row["episode_index"])
    if len(rows) < limit:
        return None
    return ["E" if row["error"] else str(int(bool(row["success"]))) for row in rows[:limit]]


def run(name: str, robot: str, out: Path, limit: int, workers: int) -> list[str]:
    run_dir = out / "runs" / f"{name}_{ARMS[robot]}"
    got = outcomes(run_dir, limit)
    if got is None:
        bench = benchmark_copy(name, robot, out)
        subprocess.run([str(Path(sys.executable).parent / "molmo-eval"), "policy=scripted", f"benchmark.path={bench}",
                        f"limit={limit}", f"workers={workers}", f"output_dir={run_dir}",
                        *(["resume=true"] if run_dir.exists() else [])], check=True)
        got = outcomes(run_dir, limit)
        if got is None:
            sys.exit(f"{run_dir}: the run ended without {limit} episodes in episodes.jsonl")
    return got


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("benchmarks", nargs="*", default=BENCHMARKS)
    parser.add_argument("--limit", type=int, default=5)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_intermixed_args()
    table = ["| benchmark | episodes | franka_droid (Panda arm) | franka_droid_fr3 | per episode (Panda / FR3) "
             "| flipped |", "|---|---|---|---|---|---|"]
    for name in args.benchmarks:
        old, new = (run(name, robot, args.out, args.limit, args.workers) for robot in ARMS)
        flips = [f"#{i}" for i, (a, b) in enumerate(zip(old, new, strict=True)) if a != b]
        table.append(f"| {name} | 0-{args.limit - 1} | {old.count('1')}/{args.limit} | {new.count('1')}/{args.limit} "
                     f"| {''.join(old)} / {''.join(new)} | {', '.join(flips) or 'none'} |")
    print("\n".join(table))


if __name__ == "__main__":
    main()
