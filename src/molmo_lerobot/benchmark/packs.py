"""Benchmark packs: the benchmarks a plugin ships (``molmo_benchmarks``), by name."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

#: the file that makes a directory a benchmark
BENCHMARK_FILE = "benchmark.json"


@dataclass(frozen=True)
class BenchmarkDir:
    """A benchmark a plugin provides: its name (``benchmark=<name>``) and its directory."""

    name: str
    path: Path


def benchmark_pack(root: str | Path) -> list[BenchmarkDir]:
    """Every benchmark directory (one holding ``benchmark.json``) right below ``root``, named after it."""
    root = Path(root)
    return [BenchmarkDir(p.name, p) for p in sorted(root.iterdir()) if (p / BENCHMARK_FILE).is_file()]
