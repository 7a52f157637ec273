"""Benchmarks: MolmoSpaces-compatible episode schema, loading with a content hash, validation, and the
generators' output helpers (the generators themselves are content: :mod:`molmo_lerobot.content`).

``load_benchmark(path, plugins)`` reads a benchmark directory or file into a :class:`Benchmark`
(each task validated with its plugin's spec model, see :mod:`.task_specs`);
``validate_benchmark(bench, plugins, scenes)`` (in :mod:`.validate`) checks it against the
installed plugins and the run's scene data.
"""

from molmo_lerobot.benchmark.load import Benchmark, BenchmarkError, Problem, load_benchmark
from molmo_lerobot.benchmark.schema import BenchmarkMetadata, EpisodeSpec

__all__ = ["Benchmark", "BenchmarkError", "BenchmarkMetadata", "EpisodeSpec", "Problem", "load_benchmark"]
