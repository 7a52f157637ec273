"""Ray actors vs the local process pool on one machine: episodes per second (target ratio >= 0.9).

Run with ``pytest -m perf tests/perf/test_ray_throughput.py -s``. Both executors run the
same scripted-expert episodes (16, or ``MOLMO_PERF_EPISODES``) on 2 workers; each is timed three times (alternating) and
the best wall time kept. "warm" Ray joins a cluster started beforehand (a cluster normally
outlives one run); "cold" includes starting the local cluster (``ray.init``).
"""

from __future__ import annotations

import json
import os
import time

import pytest

from molmo_lerobot.config import compose
from molmo_lerobot.runner.evaluate import run_evaluation

N_EPISODES = 4 * (int(os.environ.get("MOLMO_PERF_EPISODES", "16")) // 4)
WORKERS = 2
REPS = 3  # alternating; the best wall time of each is kept (the machine is shared and noisy)


@pytest.fixture(scope="module")
def bench16(tmp_path_factory):
    from molmo_lerobot.benchmark.output import write_benchmark
    from molmo_lerobot.content.tabletop.generate import generate_benchmark

    episodes, metadata = generate_benchmark("pick", 4, N_EPISODES // 4, seed=11, name="pick_perf")
    return write_benchmark(tmp_path_factory.mktemp("bench") / "pick_perf", episodes, metadata)


def _timed(bench, out, executor: str) -> float:
    cfg = compose([f"benchmark.path={bench}", f"output_dir={out}", "progress=false", "policy=scripted",
                   f"workers={WORKERS}", f"executor={executor}"])
    t0 = time.perf_counter()
    res = run_evaluation(cfg)
    wall = time.perf_counter() - t0
    assert res.summary["n_episodes"] == N_EPISODES and res.summary["n_errors"] == 0
    return wall


@pytest.mark.perf
def test_ray_throughput_matches_the_local_pool(bench16, tmp_path):
    import ray

    cold = _timed(bench16, tmp_path / "ray-cold", "ray")
    walls: dict[str, list[float]] = {"local": [], "ray": []}
    ray.init(num_cpus=WORKERS, include_dashboard=False, logging_level="WARNING")
    try:
        for rep in range(REPS):
            for ex in ("local", "ray"):
                walls[ex].append(_timed(bench16, tmp_path / f"{ex}-{rep}", ex))
    finally:
        ray.shutdown()
    local, warm = min(walls["local"]), min(walls["ray"])
    figures = {
        "episodes": N_EPISODES, "workers": WORKERS,
        "local_eps_per_s": round(N_EPISODES / local, 3), "ray_warm_eps_per_s": round(N_EPISODES / warm, 3),
        "ray_cold_eps_per_s": round(N_EPISODES / cold, 3),
        "ratio_warm": round(local / warm, 3), "ratio_cold": round(local / cold, 3),
        "walls_s": {k: [round(w, 2) for w in v] for k, v in walls.items()} | {"ray_cold": round(cold, 2)},
    }
    print("\nray-vs-local throughput:", json.dumps(figures))
