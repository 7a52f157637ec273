"""Throughput with a learned policy (issue 17 item 4, issue 28 item 2): episodes/min for a tiny ACT
(random init, no pretrained backbone, 224² exterior camera, chunks of 4 run open loop) on pick_v1
with 1, 2 and 4 workers — in process (a model per worker), served (one policy server for the run,
one request per forward) and served+batched (requests from the workers batched into one forward),
each served mode over websockets (``molmo-serve``'s protocol) and over shared memory (``shm``, the
local default) — from one run, plus the batch sizes the server saw and, per worker count, the
ratio of served+batched(shm) to in process, excluding start-up (episode time only) and wall.
Outcomes are asserted identical per episode across the modes; nothing is asserted about speed.

``pytest -m perf -s tests/perf/test_serving_throughput.py``; knobs: ``MOLMO_PERF_WORKERS``
(1,2,4), ``MOLMO_PERF_EPISODES`` (8; past pick_v1's 60 a pick benchmark of that many episodes is
generated, 10 houses as pick_v1, so ``MOLMO_PERF_EPISODES=200`` gives the issue's 200-episode figure),
``MOLMO_PERF_HORIZON`` (30 steps), ``MOLMO_PERF_DEVICE``
(auto: cuda when present), ``MOLMO_PERF_BATCH_TIMEOUT_MS``, ``MOLMO_PERF_MODES`` (all; a comma
list of the mode names below). Rows are appended to ``runs/perf.jsonl``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

pytest.importorskip("torch")
from perf_rows import append_rows, run_rates
from test_lerobot_policy import save_tiny_act

from molmo_lerobot.benchmark.output import write_benchmark
from molmo_lerobot.config import compose
from molmo_lerobot.content.tabletop.generate import generate_benchmark
from molmo_lerobot.runner.evaluate import run_evaluation

pytestmark = pytest.mark.perf
WORKERS = [int(w) for w in os.environ.get("MOLMO_PERF_WORKERS", "1,2,4").split(",")]
EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "8"))
HORIZON = int(os.environ.get("MOLMO_PERF_HORIZON", "30"))
DEVICE = os.environ.get("MOLMO_PERF_DEVICE", "auto")
BATCH_TIMEOUT_MS = os.environ.get("MOLMO_PERF_BATCH_TIMEOUT_MS")  # default: policy.serve_batch_timeout_ms
_BATCHED = ["policy.serve=true"] + ([f"policy.serve_batch_timeout_ms={BATCH_TIMEOUT_MS}"] if BATCH_TIMEOUT_MS else [])
MODES = {
    "in-process": [],
    "served(ws)": ["policy.serve=true", "policy.serve_max_batch=1", "policy.serve_transport=websocket"],
    "served+batched(ws)": [*_BATCHED, "policy.serve_transport=websocket"],
    "served(shm)": ["policy.serve=true", "policy.serve_max_batch=1", "policy.serve_transport=shm"],
    "served+batched(shm)": [*_BATCHED, "policy.serve_transport=shm"],
}
SELECTED = os.environ.get("MOLMO_PERF_MODES", ",".join(MODES)).split(",")
PICK_V1_EPISODES = 60


def _pick_benchmark(tmp_path: Path) -> list[str]:
    """pick_v1, or a pick benchmark from pick_v1's generator and seed with 10 houses x ceil(EPISODES / 10)
    episodes when EPISODES exceed pick_v1 (``limit`` then takes the first EPISODES)."""
    if EPISODES <= PICK_V1_EPISODES:
        return ["benchmark=pick_v1"]
    episodes, meta = generate_benchmark("pick", 10, -(-EPISODES // 10), 0, "pick_perf")
    return ["benchmark=pick_v1", "benchmark.name=pick_perf",
            f"benchmark.path={write_benchmark(tmp_path / 'pick_perf', episodes, meta)}"]


def test_throughput_in_process_vs_served_vs_batched(tmp_path):
    act = save_tiny_act(tmp_path / "act", image_hw=(224, 224))
    benchmark = _pick_benchmark(tmp_path)
    rows, outcomes = [], {}
    for workers in WORKERS:
        for mode in ["in-process", *(m for m in SELECTED if m != "in-process")]:
            extra = MODES[mode]
            out = tmp_path / f"{re.sub(r'[^a-z]+', '-', mode)}{workers}"
            cfg = compose(["policy=lerobot", f"policy.path={act}", f"policy.device={DEVICE}", "policy.mode=chunk",
                           "+policy.cameras.exterior=observation.images.front", *benchmark,
                           f"limit={EPISODES}", f"horizon={HORIZON}", f"workers={workers}", f"output_dir={out}",
                           "progress=false", *extra])
            res = run_evaluation(cfg)
            outcomes[(mode, workers)] = [(e.episode_index, e.success, e.success_once, e.steps, e.error)
                                         for e in res.episodes]
            row, stats = run_rates(res, workers, out)
            rows.append({"mode": mode, **row, "batch_sizes": stats.get("batch_sizes")})
    base = {r["workers"]: r for r in rows if r["mode"] == "in-process"}
    one = base[WORKERS[0]]["eps_per_min"]
    name = "pick_v1" if len(benchmark) == 1 else "a generated pick benchmark"
    print(f"\ntiny ACT on {name}, {EPISODES} episodes x {HORIZON} steps, device={DEVICE}, "
          f"batch timeout {BATCH_TIMEOUT_MS or 'default'} ms")
    print(f"{'mode':>19} {'workers':>7} {'wall s':>8} {'eps/min':>8} {'excl. start':>11} {'vs in-proc':>10} "
          f"{'excl. vs':>8} {'vs w=1':>7}  batch sizes (size: batches)")
    for r in rows:
        b = base[r["workers"]]
        r["vs_in_process_wall"] = round(r["eps_per_min"] / b["eps_per_min"], 3)
        r["vs_in_process_excl_startup"] = (round(r["eps_per_min_excl_startup"] / b["eps_per_min_excl_startup"], 3)
                                           if r["eps_per_min_excl_startup"] and b["eps_per_min_excl_startup"] else None)
        print(f"{r['mode']:>19} {r['workers']:>7} {r['wall_s']:>8.1f} {r['eps_per_min']:>8.2f} "
              f"{r['eps_per_min_excl_startup'] or 0:>11.2f} {r['vs_in_process_wall']:>10.2f} "
              f"{r['vs_in_process_excl_startup'] or 0:>8.2f} {r['eps_per_min'] / one:>7.2f}  {r['batch_sizes'] or '-'}")
    append_rows("serving_throughput", rows, horizon=HORIZON, device=DEVICE)
    reference = outcomes[("in-process", WORKERS[0])]
    assert all(o == reference for o in outcomes.values()), "per-episode outcomes differ between modes"
    assert all(r["errors"] == 0 for r in rows)
