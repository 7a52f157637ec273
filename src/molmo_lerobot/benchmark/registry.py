"""Benchmarks by name: one lookup for the shipped benchmarks and those plugins ship.

A plugin provides benchmarks with the ``molmo_benchmarks`` hook (usually every benchmark directory
of a folder it ships, :func:`~molmo_lerobot.benchmark.packs.benchmark_pack`). Ours are the
repository's (or the wheel's) ``benchmarks/``, provided by the built-in ``core_config`` plugin. A name two
plugins provide is a clash like any other (``plugins.prefer.benchmark.<name>=<plugin>``).
``molmo-eval benchmark=<name>``, the Gymnasium ids and ``molmo-bench validate <name>`` all look
names up here.
"""

from __future__ import annotations

from pathlib import Path

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.plugins import PluginConflict, PluginError, Plugins


class UnknownBenchmark(MolmoError, LookupError):
    """Neither a path nor the name of a registered benchmark; the message lists the names."""


def benchmark_names(plugins: Plugins) -> list[str]:
    """The names of every registered benchmark, sorted."""
    return plugins.names("benchmark")


def benchmark_dir(name: str, plugins: Plugins) -> Path:
    """The directory of the registered benchmark ``name``."""
    try:
        return Path(plugins.resolve("benchmark", name).path)
    except PluginConflict:
        raise
    except PluginError as exc:
        raise UnknownBenchmark(str(exc)) from None


def find_benchmark(benchmark: str | Path, plugins: Plugins) -> Path:
    """``benchmark`` as a path (a benchmark directory or JSON file) where one exists, else the
    registered benchmark of that name; one clear error otherwise."""
    path = Path(str(benchmark)).expanduser()
    if path.exists():
        return path
    try:
        return benchmark_dir(str(benchmark), plugins)
    except UnknownBenchmark:
        raise UnknownBenchmark(f"unknown benchmark {str(benchmark)!r}: neither a path nor a registered benchmark "
                               f"({', '.join(benchmark_names(plugins))})") from None
