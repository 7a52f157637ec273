"""Throughput with a learned policy (issue 17 item 4): episodes/min for a tiny ACT (random init,
no pretrained backbone, 224² exterior camera, chunks of 4 run open loop) on pick_v1 with 1, 2 and 4 workers — in process
(a model per worker), served (one ``molmo-serve`` for the run, one request per forward) and
served+batched (requests from the workers batched into one forward) — from one run, plus the
batch sizes the server saw. Outcomes are asserted identical per episode across the three modes;
nothing is asserted about speed.

``pytest -m perf -s tests/perf/test_serving_throughput.py``; knobs: ``MOLMO_PERF_WORKERS``
(1,2,4), ``MOLMO_PERF_EPISODES`` (8), ``MOLMO_PERF_HORIZON`` (30 steps), ``MOLMO_PERF_DEVICE``
(auto: cuda when present), ``MOLMO_PERF_BATCH_TIMEOUT_MS``. Rows are appended to ``runs/perf.jsonl``.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

pytest.importorskip("torch")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "policies"))
from test_lerobot_policy import save_tiny_act

from molmo_lerobot.config import compose
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.serving.run_server import STATS_FILE

pytestmark = pytest.mark.perf
WORKERS = [int(w) for w in os.environ.get("MOLMO_PERF_WORKERS", "1,2,4").split(",")]
EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "8"))
HORIZON = int(os.environ.get("MOLMO_PERF_HORIZON", "30"))
DEVICE = os.environ.get("MOLMO_PERF_DEVICE", "auto")
BATCH_TIMEOUT_MS = os.environ.get("MOLMO_PERF_BATCH_TIMEOUT_MS")  # default: policy.serve_batch_timeout_ms
MODES = {
    "in-process": [],
    "served": ["policy.serve=true", "policy.serve_max_batch=1"],
    "served+batched": ["policy.serve=true"] + ([f"policy.serve_batch_timeout_ms={BATCH_TIMEOUT_MS}"]
                                               if BATCH_TIMEOUT_MS else []),
}


def test_throughput_in_process_vs_served_vs_batched(tmp_path):
    act = save_tiny_act(tmp_path / "act", image_hw=(224, 224))
    rows, outcomes = [], {}
    for workers in WORKERS:
        for mode, extra in MODES.items():
            out = tmp_path / f"{mode}-{workers}"
            cfg = compose(["policy=lerobot", f"policy.path={act}", f"policy.device={DEVICE}", "policy.mode=chunk",
                           "+policy.cameras.exterior=observation.images.front", "benchmark=pick_v1",
                           f"limit={EPISODES}", f"horizon={HORIZON}", f"workers={workers}", f"output_dir={out}",
                           "progress=false", *extra])
            res = run_evaluation(cfg)
            outcomes[(mode, workers)] = [(e.episode_index, e.success, e.success_once, e.steps, e.error)
                                         for e in res.episodes]
            wall = res.summary["wall_time_s"]
            busy = sum(e.duration_s or 0.0 for e in res.episodes) / workers
            stats = json.loads((out / STATS_FILE).read_text()) if (out / STATS_FILE).exists() else {}
            rows.append({"mode": mode, "workers": workers, "episodes": len(res.episodes), "wall_s": round(wall, 2),
                         "eps_per_min": round(60 * len(res.episodes) / wall, 2),
                         "eps_per_min_excl_startup": round(60 * len(res.episodes) / busy, 2) if busy else None,
                         "batch_sizes": stats.get("batch_sizes"), "errors": res.summary["n_errors"]})
    base = {r["workers"]: r for r in rows if r["mode"] == "in-process"}
    one = base[WORKERS[0]]["eps_per_min"]
    print(f"\ntiny ACT on pick_v1, {EPISODES} episodes x {HORIZON} steps, device={DEVICE}, "
          f"batch timeout {BATCH_TIMEOUT_MS or 'default'} ms")
    print(f"{'mode':>15} {'workers':>7} {'wall s':>8} {'eps/min':>8} {'excl. start':>11} {'vs in-proc':>10} "
          f"{'vs w=1':>7}  batch sizes (size: batches)")
    for r in rows:
        vs_in = r["eps_per_min"] / base[r["workers"]]["eps_per_min"]
        print(f"{r['mode']:>15} {r['workers']:>7} {r['wall_s']:>8.1f} {r['eps_per_min']:>8.2f} "
              f"{r['eps_per_min_excl_startup'] or 0:>11.2f} {vs_in:>10.2f} {r['eps_per_min'] / one:>7.2f}  "
              f"{r['batch_sizes'] or '-'}")
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        for r in rows:
            f.write(json.dumps({"benchmark": "serving_throughput", "horizon": HORIZON, "device": DEVICE, **r}) + "\n")
    reference = outcomes[("in-process", WORKERS[0])]
    assert all(o == reference for o in outcomes.values()), "per-episode outcomes differ between modes"
    assert all(r["errors"] == 0 for r in rows)
