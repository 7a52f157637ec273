"""Which benchmark episodes a run evaluates: ``limit=K``, ``episodes=[…]`` or ``sample=K``.

* ``limit=K``: the first K episodes (benchmark order; shipped benchmarks are grouped by house, so
  these are the first houses' episodes);
* ``episodes=[i, j, …]``: exactly these benchmark indices;
* ``sample=K``: K episodes spread over the benchmark, stratified by (house, task): the strata are
  visited in a random order, round after round, each round taking one not yet taken episode of
  every stratum, so each (house, task) gets ``K // strata`` or one more. The draw is seeded by the
  run's ``seed``: the same benchmark, K and seed select the same episodes (a resume, or another
  policy's run to compare with).

At most one of the three may be given. The selection is recorded in ``run.json`` and
``results.json`` (``selection``: its kind, its parameters and the indices) and a resume must make
the same one.
"""

from __future__ import annotations

from collections import defaultdict
from typing import TYPE_CHECKING, Any

import numpy as np

from molmo_lerobot.errors import RunError

if TYPE_CHECKING:
    from molmo_lerobot.benchmark_kinds import BenchmarkEpisodes
    from molmo_lerobot.run_config import RunConfig


def selection_of(config: RunConfig, bench: BenchmarkEpisodes) -> tuple[list[int], dict[str, Any] | None]:
    """The benchmark indices the run evaluates, in order, and the ``selection`` record (None for
    ``limit`` or every episode: ``limit`` is recorded by itself). Raises :class:`RunError` (one line
    naming the benchmark file and the index) for an index outside the benchmark."""
    n = len(bench.episodes)
    if config.episodes is not None:
        outside = [i for i in config.episodes if not 0 <= i < n]
        if outside:
            raise RunError(f"episodes: index {outside[0]} is outside benchmark {bench.name!r} "
                           f"({bench.origins[0].file if bench.origins else bench.path}: {n} episodes, 0..{n - 1})")
        chosen = sorted(config.episodes)
        return chosen, {"kind": "episodes", "episodes": chosen}
    if config.sample is not None:
        chosen = stratified_sample(bench, config.sample, config.seed)
        return chosen, {"kind": "sample", "sample": config.sample, "seed": config.seed,
                        "strata": "house_index, task", "episodes": chosen}
    return list(range(n))[:config.limit], None


def stratified_sample(bench: BenchmarkEpisodes, k: int, seed: int) -> list[int]:
    """``k`` benchmark indices (all if ``k`` >= the benchmark) spread over its (house, task) strata."""
    strata: dict[tuple[int, str], list[int]] = defaultdict(list)
    for i, ep in enumerate(bench.episodes):
        strata[(int(ep.house_index), ep.task.task_name)].append(i)
    rng = np.random.default_rng([seed, k])
    keys = sorted(strata)
    order = [keys[j] for j in rng.permutation(len(keys))]
    queues = {key: [strata[key][j] for j in rng.permutation(len(strata[key]))] for key in order}
    chosen: list[int] = []
    for round_ in range(max(len(q) for q in queues.values())):
        for key in order:
            if len(chosen) == k:
                return sorted(chosen)
            if round_ < len(queues[key]):
                chosen.append(queues[key][round_])
    return sorted(chosen)
