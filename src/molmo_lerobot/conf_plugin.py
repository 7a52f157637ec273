"""Built-in plugin contributing the core Hydra config directory (``conf/``), the shipped benchmarks
(``benchmarks/``) and the benchmark kind that runs them and every other episode file (``episodes``, asked last)."""

from __future__ import annotations

from typing import Any

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.packs import BenchmarkDir, benchmark_pack
from molmo_lerobot.paths import data_path


@hookimpl
def molmo_config_dirs() -> list[str]:
    return [str(data_path("conf"))]


@hookimpl
def molmo_benchmarks() -> list[BenchmarkDir]:
    return benchmark_pack(data_path("benchmarks"))


@hookimpl(trylast=True)
def molmo_benchmark_kinds() -> list[Any]:
    from molmo_lerobot.runner.episode_files import EpisodeFilesKind

    return [EpisodeFilesKind()]
