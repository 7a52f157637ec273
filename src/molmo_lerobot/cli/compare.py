"""``molmo-compare RUN_A RUN_B [--metric success|success_once] [--json] [--allow-different-trials]``: paired
comparison of two runs of the same trial."""

from __future__ import annotations

import argparse
import json
import sys

from molmo_lerobot.namespaces import NamespaceError, resolve_run
from molmo_lerobot.runner.compare import METRICS, CompareError, compare_runs, format_report, load_run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="molmo-compare",
        description="Compare two runs of the same benchmark on their shared episodes: exact McNemar test, "
                    "paired difference of success rates (B - A) with a 95% CI, per-task table.")
    parser.add_argument("run_a", help="output_dir of the first run (A, the baseline), or its recording's dataset_id")
    parser.add_argument("run_b", help="output_dir of the second run (B), or its recording's dataset_id")
    parser.add_argument("--metric", choices=sorted(METRICS), default="success",
                        help="success (at the final step, the primary metric) or success_once (at any step)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--allow-different-trials", action="store_true",
                        help="compare runs whose timing, horizons, eval options or thresholds differ "
                             "(each difference is listed in the notes)")
    args = parser.parse_args(argv)
    try:
        run_a, run_b = load_run(resolve_run(args.run_a)), load_run(resolve_run(args.run_b))
        report = compare_runs(run_a, run_b, metric=args.metric,
                              allow_different_trials=args.allow_different_trials)
    except (CompareError, NamespaceError) as exc:
        print(f"molmo-compare: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(report, indent=2) if args.json else format_report(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
