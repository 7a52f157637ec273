"""Built-in plugin contributing the core Hydra config directory (``conf/``) and the shipped benchmarks
(``benchmarks/``)."""

from __future__ import annotations

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.packs import BenchmarkDir, benchmark_pack
from molmo_lerobot.paths import data_path


@hookimpl
def molmo_config_dirs() -> list[str]:
    return [str(data_path("conf"))]


@hookimpl
def molmo_benchmarks() -> list[BenchmarkDir]:
    return benchmark_pack(data_path("benchmarks"))
