"""Built-in plugin contributing the core Hydra config directory (``conf/``), the shipped benchmarks
(``benchmarks/``), the built-in executors (``executor=local|ray``) and the benchmark kind that runs the shipped
benchmarks and every other episode file (``episodes``, asked last)."""

from __future__ import annotations

from typing import Any

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.packs import BenchmarkDir, benchmark_pack
from molmo_lerobot.executor_types import ExecutorType
from molmo_lerobot.paths import data_path
from molmo_lerobot.runner.builtin_executors import LOCAL, RAY


@hookimpl
def molmo_config_dirs() -> list[str]:
    return [str(data_path("conf"))]


@hookimpl
def molmo_benchmarks() -> list[BenchmarkDir]:
    return benchmark_pack(data_path("benchmarks"))


@hookimpl
def molmo_executors() -> list[ExecutorType]:
    return [LOCAL, RAY]


@hookimpl(trylast=True)
def molmo_benchmark_kinds() -> list[Any]:
    from molmo_lerobot.runner.episode_files import EpisodeFilesKind

    return [EpisodeFilesKind()]
