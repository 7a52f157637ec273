"""The scripted expert's per-episode outcomes with MuJoCo body sleeping off and on (``timing.sleep``),
benchmark by benchmark: the evidence for the sleeping decision in docs/parity.md ("Sleep").

    python tests/parity/sleep_outcomes.py OUT_DIR [--limit K] [--workers N] [BENCHMARK ...]

runs ``molmo-eval policy=scripted seed=0`` twice per benchmark (``timing.sleep=false`` and ``true``)
into ``OUT_DIR/<benchmark>-sleep-<off|on>``, then prints one table row per benchmark (episodes, successes
each way, the episodes whose outcome flips) and each flipped episode. A run already complete in
``OUT_DIR`` is reused (``resume=true``), so an interrupted measurement goes on where it stopped. Without
``--limit`` every episode runs. Default benchmarks: v1, v2, door_v1, nav_v1 of every task type (v3 has
v2's episodes and physics).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

BENCHMARKS = ("pick_v1", "pick_and_place_v1", "next_to_v1", "color_v1", "open_v1", "close_v1",
              "pick_v2", "pick_and_place_v2", "next_to_v2", "color_v2", "open_v2", "close_v2",
              "door_v1", "nav_v1")


def run(out: Path, benchmark: str, sleep: bool, limit: int | None, workers: int) -> dict[int, bool]:
    """One scripted run; its per-episode successes by episode index (errors raise)."""
    out.mkdir(parents=True, exist_ok=True)
    args = [sys.executable, "-m", "molmo_lerobot.cli.eval", "policy=scripted", f"benchmark={benchmark}", "seed=0",
            f"workers={workers}", f"timing.sleep={str(sleep).lower()}", f"output_dir={out}", "resume=true"]
    if limit is not None:
        args.append(f"limit={limit}")
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    outcomes = {}
    for line in (out / "episodes.jsonl").read_text().splitlines():
        row = json.loads(line)
        if row.get("error"):
            raise RuntimeError(f"{out}: episode {row['episode_index']}: {row['error']}")
        outcomes[row["episode_index"]] = bool(row["success"])
    return outcomes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("benchmarks", nargs="*", default=list(BENCHMARKS))
    parser.add_argument("--limit", type=int, default=None)
    parser.add_argument("--workers", type=int, default=2)
    a = parser.parse_intermixed_args(argv)
    print("| benchmark | episodes | scripted, sleep off | scripted, sleep on | outcomes flipped |")
    print("|---|---|---|---|---|")
    flips = []
    for bench in a.benchmarks:
        off, on = (run(a.out / f"{bench}-sleep-{w}", bench, w == "on", a.limit, a.workers) for w in ("off", "on"))
        flipped = sorted(i for i in off if on.get(i) != off[i])
        flips += [f"{bench} #{i}: sleep off {'success' if off[i] else 'failure'}, "
                  f"on {'success' if on.get(i) else 'failure'}" for i in flipped]
        print(f"| {bench} | {len(off)} | {sum(off.values())} | {sum(on.values())} | "
              f"{', '.join(f'#{i}' for i in flipped) or 'none'} |", flush=True)
    print("\n".join(flips))
    return 0


if __name__ == "__main__":
    sys.exit(main())
