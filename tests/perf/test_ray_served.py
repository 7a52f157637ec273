"""Per-node policy servers on a local two-node Ray cluster (issue 28 item 5): episodes/min and the
head's cost per episode, against the one-box modes doing the same work.

A tiny ACT (random init, 224² exterior camera, chunks run open loop) on pick_v1, from one run:

* ``local in-process`` — the local pool, a model per worker (the baseline);
* ``local served`` — the local pool and one ``molmo-serve`` for the run (batched);
* ``ray 1 node`` — ``executor=ray policy.serve=true`` with one worker (one node's server used);
* ``ray 2 nodes`` — the same with one worker per node: each node's worker talks to its node's server;
* ``ray 2 nodes + record`` — the same, recording the LeRobot dataset (the head merges the shards).

The "nodes" are raylets on this machine (``ray.cluster_utils.Cluster``, one CPU each), so they share
its cores: the figures show the routing and the head's cost, not a real multi-machine speed-up.
``head_cpu_ms_per_episode`` is the CPU time of the evaluating process (planning, the supervisor,
results, Ray's driver threads, finalizers) per episode: one head core saturates at
``60000 / head_cpu_ms_per_episode`` episodes/min (docs/scaling.md). ``bytes_to_workers`` and
``bytes_from_workers`` are what crosses between the head and a worker per episode (the pickled plan,
the result). Outcomes are asserted equal per episode across modes; nothing is asserted about speed.

``pytest -m perf -s tests/perf/test_ray_served.py``; knobs ``MOLMO_PERF_EPISODES`` (8),
``MOLMO_PERF_HORIZON`` (30 steps). Rows are appended to ``runs/perf.jsonl``.
"""

from __future__ import annotations

import json
import os
import pickle
import resource
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("torch")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "policies"))
from test_lerobot_policy import save_tiny_act

from molmo_lerobot.config import compose
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.serving.run_server import STATS_FILE

pytestmark = pytest.mark.perf
EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "8"))
HORIZON = int(os.environ.get("MOLMO_PERF_HORIZON", "30"))
MODES = {  # name: (workers, overrides)
    "local in-process": (2, []),
    "local served": (2, ["policy.serve=true"]),
    "ray 1 node": (1, ["executor=ray", "policy.serve=true"]),
    "ray 2 nodes": (2, ["executor=ray", "policy.serve=true"]),
    "ray 2 nodes + record": (2, ["executor=ray", "policy.serve=true", "record=true"]),
}


def _cpu_self() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def _bytes_per_episode(cfg, res) -> tuple[int, int]:
    """Pickled size of an episode's plan (head → worker) and of its result (worker → head)."""
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.runner.evaluate import resolve_benchmark_path
    from molmo_lerobot.runner.plan import EpisodePlanner
    from molmo_lerobot.runner.run_config import RunConfig

    plain = RunConfig.of(cfg).plain()
    ctx = RunContext.build(plain)
    planner = EpisodePlanner(ctx, load_benchmark(resolve_benchmark_path(plain["benchmark"]), ctx.plugins))
    plan = max(len(pickle.dumps(planner.plan(e.episode_index))) for e in res.episodes)
    result = max(len(pickle.dumps(e.to_dict())) for e in res.episodes)
    return plan, result


def test_ray_per_node_servers_vs_one_box(tmp_path):
    import ray
    from ray.cluster_utils import Cluster

    act = save_tiny_act(tmp_path / "act", image_hw=(224, 224))
    t0 = time.perf_counter()
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="WARNING")
    cluster_s = time.perf_counter() - t0
    rows, outcomes, sizes = [], {}, None
    try:
        for mode, (workers, extra) in MODES.items():
            out = tmp_path / mode.replace(" ", "_")
            cfg = compose(["policy=lerobot", f"policy.path={act}", "policy.device=cpu", "policy.mode=chunk",
                           "+policy.cameras.exterior=observation.images.front", "benchmark=pick_v1",
                           f"limit={EPISODES}", f"horizon={HORIZON}", f"workers={workers}", f"output_dir={out}",
                           "progress=false", *extra])
            cpu0 = _cpu_self()
            res = run_evaluation(cfg)
            head_cpu = _cpu_self() - cpu0
            outcomes[mode] = [(e.episode_index, e.success, e.success_once, e.steps, e.error) for e in res.episodes]
            wall = res.summary["wall_time_s"]
            busy = sum(e.duration_s or 0.0 for e in res.episodes) / workers
            stats = json.loads((out / STATS_FILE).read_text()) if (out / STATS_FILE).exists() else {}
            per_node = ({nid[:8]: {"served": s["served"], "batch_sizes": s["batch_sizes"]}
                         for nid, s in stats["nodes"].items()} if "nodes" in stats else None)
            rows.append({"mode": mode, "workers": workers, "episodes": len(res.episodes), "wall_s": round(wall, 2),
                         "eps_per_min": round(60 * len(res.episodes) / wall, 2),
                         "eps_per_min_excl_startup": round(60 * len(res.episodes) / busy, 2) if busy else None,
                         "head_cpu_ms_per_episode": round(1000 * head_cpu / len(res.episodes), 1),
                         "batch_sizes": stats.get("batch_sizes"), "per_node": per_node,
                         "errors": res.summary["n_errors"]})
            if sizes is None:
                sizes = _bytes_per_episode(cfg, res)
    finally:
        ray.shutdown()
        cluster.shutdown()
    base = rows[0]["eps_per_min"]
    print(f"\ntiny ACT on pick_v1, {EPISODES} episodes x {HORIZON} steps, CPU; 2-node local cluster started in "
          f"{cluster_s:.1f} s; per episode {sizes[0]} B plan to the worker, {sizes[1]} B result back")
    print(f"{'mode':>21} {'workers':>7} {'wall s':>7} {'eps/min':>8} {'excl. start':>11} {'vs base':>7} "
          f"{'head ms/ep':>10}  batch sizes / per node")
    for r in rows:
        print(f"{r['mode']:>21} {r['workers']:>7} {r['wall_s']:>7.1f} {r['eps_per_min']:>8.2f} "
              f"{r['eps_per_min_excl_startup'] or 0:>11.2f} {r['eps_per_min'] / base:>7.2f} "
              f"{r['head_cpu_ms_per_episode']:>10.1f}  {r['per_node'] or r['batch_sizes'] or '-'}")
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        for r in rows:
            f.write(json.dumps({"benchmark": "ray_served", "horizon": HORIZON, "cluster_start_s": round(cluster_s, 2),
                                "bytes_to_workers": sizes[0], "bytes_from_workers": sizes[1], **r}) + "\n")
    reference = outcomes["local in-process"]
    assert all(o == reference for o in outcomes.values()), "per-episode outcomes differ between modes"
    assert all(r["errors"] == 0 for r in rows)
    two = next(r for r in rows if r["mode"] == "ray 2 nodes")
    assert len(two["per_node"]) == 2 and all(n["served"] > 0 for n in two["per_node"].values())
