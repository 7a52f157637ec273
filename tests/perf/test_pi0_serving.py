"""A π0-class figure (issue 28 item 4): LeRobot's PI0 (or PI0.5) at random init, served with
dynamic batching. Two tables from one run:

1. Forward latency and memory per batch size (1 … 32): ``policy=pi0 policy.path=<random-init
   checkpoint>`` loaded as the server loads it, B forks answered by one ``act_batch`` (LeRobot's
   pre-processing, 10 denoising steps over a 50-step chunk, post-processing, the DROID action
   mapping), median of ``MOLMO_PERF_REPEATS`` after a warm-up call. Memory: on CUDA
   ``torch.cuda.max_memory_allocated`` during the call (peak reset before it); on CPU the
   process's resident set after the call and its peak so far (batches run in increasing order).
2. End-to-end episodes/min on pick_v1 with ``policy.serve=true`` (one ``molmo-serve`` for the
   run's N workers): unbatched (``serve_max_batch=1``, the baseline doing the same work) and
   batched, with the batch sizes the server saw.

The checkpoint is made here (``molmo_pi0.random_init``; weights random, tokenizer a stand-in) at
``MOLMO_PERF_PI0_SIZE``: ``small`` (default: PI0's structure and sequence lengths, ~4 M parameters,
for the curve's shape on CPU) or ``full`` (PaliGemma 3B + the 300M expert, for a GPU).
PI0 draws its flow-matching noise per batch item, so per-episode outcomes are not compared
across modes. Nothing is asserted about speed.

``pytest -m perf -s tests/perf/test_pi0_serving.py``; knobs: ``MOLMO_PERF_PI0_SIZE`` (small),
``MOLMO_PERF_PI0_TYPE`` (pi0 | pi05), ``MOLMO_PERF_PI0_DTYPE`` (float32 | bfloat16),
``MOLMO_PERF_PI0_PATH`` (an existing checkpoint instead), ``MOLMO_PERF_BATCHES``
(1,2,4,8,16,32), ``MOLMO_PERF_REPEATS`` (3), ``MOLMO_PERF_THREADS`` (CPU threads of table 1;
1: what a served run's server gets by default, ``worker_threads``), ``MOLMO_PERF_DEVICE`` (auto),
``MOLMO_PERF_WORKERS`` (4), ``MOLMO_PERF_EPISODES`` (8), ``MOLMO_PERF_HORIZON`` (24 steps: 3
requests of 8 actions). Needs ``molmo-pi0[inprocess]`` (transformers). Rows are appended to ``runs/perf.jsonl``.
"""

from __future__ import annotations

import os
import resource
import statistics
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("transformers")
from perf_rows import append_rows, run_rates

from molmo_lerobot.config import compose
from molmo_lerobot.cpu_threads import cap_threads
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_pi0.plugin import make_pi0_policy
from molmo_pi0.random_init import save_random_pi0

pytestmark = pytest.mark.perf
SIZE = os.environ.get("MOLMO_PERF_PI0_SIZE", "small")
KIND = os.environ.get("MOLMO_PERF_PI0_TYPE", "pi0")
DTYPE = os.environ.get("MOLMO_PERF_PI0_DTYPE", "float32")
PATH = os.environ.get("MOLMO_PERF_PI0_PATH")
BATCHES = [int(b) for b in os.environ.get("MOLMO_PERF_BATCHES", "1,2,4,8,16,32").split(",")]
REPEATS = int(os.environ.get("MOLMO_PERF_REPEATS", "3"))
THREADS = int(os.environ.get("MOLMO_PERF_THREADS", "1"))
DEVICE = os.environ.get("MOLMO_PERF_DEVICE", "auto")
WORKERS = int(os.environ.get("MOLMO_PERF_WORKERS", "4"))
EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "8"))
HORIZON = int(os.environ.get("MOLMO_PERF_HORIZON", "24"))
PROMPT = "pick up the white cup"


def _observation(rng: np.random.Generator) -> dict:
    return {"images": {c: rng.integers(0, 255, (224, 224, 3), dtype=np.uint8) for c in ("exterior", "wrist")},
            "qpos": {"arm": rng.uniform(-1, 1, 7), "gripper": np.zeros(1)}, "prompt": PROMPT}


def _rss_mb() -> tuple[float, float]:
    """(resident now, peak so far) of this process, MiB."""
    now = next(int(line.split()[1]) for line in Path("/proc/self/status").read_text().splitlines()
               if line.startswith("VmRSS:")) / 1024
    return now, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _latency_rows(path: str) -> list[dict]:
    import torch

    cap_threads(THREADS)
    rss_before_mb = _rss_mb()[0]
    t0 = time.perf_counter()
    policy = make_pi0_policy({"name": "pi0", "path": path, "device": DEVICE})
    load_s = time.perf_counter() - t0
    model = policy.inner.policy
    cuda = policy.inner.device.startswith("cuda")
    params = sum(p.numel() for p in model.parameters())
    weights_mb = (torch.cuda.memory_allocated() if cuda else sum(p.numel() * p.element_size()
                                                                  for p in model.parameters())) / 2**20
    rng = np.random.default_rng(0)
    rows = []
    for batch in BATCHES:
        forks = [policy.fork() for _ in range(batch)]
        for i, fork in enumerate(forks):
            fork.reset(EpisodeContext(spec=None, episode_index=i, seed=i, prompt=PROMPT,  # type: ignore[arg-type]
                                      move_groups={"arm": 7, "gripper": 1}, policy_dt_s=0.066))
        observations = [_observation(rng) for _ in range(batch)]
        type(policy).act_batch(forks, observations)  # warm-up (allocator, kernels)
        if cuda:
            torch.cuda.synchronize()
            torch.cuda.reset_peak_memory_stats()
        times = []
        for _ in range(REPEATS):
            t = time.perf_counter()
            answers = type(policy).act_batch(forks, observations)
            times.append(time.perf_counter() - t)
        errors = [a for a in answers if isinstance(a, Exception)]
        assert not errors, f"batch {batch}: {errors[0]}"
        latency = statistics.median(times)
        row = {"batch": batch, "latency_ms": round(1000 * latency, 1),
               "per_item_ms": round(1000 * latency / batch, 1), "items_per_s": round(batch / latency, 2)}
        if cuda:
            row["gpu_peak_mb"] = round(torch.cuda.max_memory_allocated() / 2**20, 1)
        else:
            row["rss_mb"], row["rss_peak_mb"] = (round(v, 1) for v in _rss_mb())
        rows.append(row)
    policy.close()
    for row in rows:
        row.update(params=params, weights_mb=round(weights_mb, 1), load_s=round(load_s, 1),
                   rss_before_load_mb=round(rss_before_mb, 1),
                   device=policy.inner.device, threads=THREADS)
    return rows


def _throughput_rows(path: str, tmp_path: Path) -> list[dict]:
    rows = []
    for mode, extra in (("served", ["policy.serve_max_batch=1"]), ("served+batched", [])):
        out = tmp_path / mode
        cfg = compose(["policy=pi0", f"policy.path={path}", f"policy.device={DEVICE}", "policy.serve=true",
                       "benchmark=pick_v1", f"limit={EPISODES}", f"horizon={HORIZON}", f"workers={WORKERS}",
                       f"output_dir={out}", "progress=false", *extra])
        res = run_evaluation(cfg)
        row, stats = run_rates(res, WORKERS, out)
        rows.append({"mode": mode, **row, "requests": stats.get("served"), "batch_sizes": stats.get("batch_sizes")})
    return rows


def test_pi0_latency_memory_and_served_throughput(tmp_path):
    t0 = time.perf_counter()
    path = PATH or str(save_random_pi0(tmp_path / "ckpt", size=SIZE, kind=KIND, dtype=DTYPE))  # type: ignore[arg-type]
    make_s = time.perf_counter() - t0
    latency = _latency_rows(path)
    throughput = _throughput_rows(path, tmp_path)
    first = latency[0]
    print(f"\n{KIND} size={SIZE} dtype={DTYPE} random init: {first['params'] / 1e6:.1f} M parameters, "
          f"weights {first['weights_mb']:.0f} MiB, made in {make_s:.1f} s, loaded in {first['load_s']:.1f} s, "
          f"device={first['device']}, {THREADS} CPU thread(s); "
          f"RSS before loading {first['rss_before_load_mb']:.0f} MiB")
    mem = "GPU peak MiB" if "gpu_peak_mb" in first else "RSS MiB (peak)"
    print(f"{'batch':>5} {'latency ms':>10} {'per item ms':>11} {'items/s':>8} {'vs b=1':>7}  {mem}")
    for r in latency:
        mem_v = f"{r['gpu_peak_mb']:.0f}" if "gpu_peak_mb" in r else f"{r['rss_mb']:.0f} ({r['rss_peak_mb']:.0f})"
        print(f"{r['batch']:>5} {r['latency_ms']:>10.1f} {r['per_item_ms']:>11.1f} {r['items_per_s']:>8.2f} "
              f"{r['items_per_s'] / first['items_per_s']:>7.2f}  {mem_v}")
    print(f"pick_v1, {EPISODES} episodes x {HORIZON} steps, {WORKERS} workers, policy.serve=true")
    print(f"{'mode':>15} {'wall s':>8} {'eps/min':>8} {'excl. start':>11} {'vs served':>9}  "
          "batch sizes (size: batches)")
    for r in throughput:
        print(f"{r['mode']:>15} {r['wall_s']:>8.1f} {r['eps_per_min']:>8.2f} "
              f"{r['eps_per_min_excl_startup'] or 0:>11.2f} "
              f"{r['eps_per_min'] / throughput[0]['eps_per_min']:>9.2f}  {r['batch_sizes'] or '-'}")
    common = {"policy": KIND, "size": SIZE, "dtype": DTYPE, "device_requested": DEVICE}
    append_rows("pi0_serving_latency", latency, **common)
    append_rows("pi0_serving_throughput", throughput, **common, horizon=HORIZON)
    assert all(r["errors"] == 0 for r in throughput)
