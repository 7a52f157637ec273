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
the result); ``dataset_bytes_per_episode`` what a recording worker writes to the output directory
(a shared file system on a real cluster). Outcomes are asserted equal per episode across modes;
nothing is asserted about speed.

A second test measures the head's *marginal* CPU per episode (two run sizes, without and with
recording), the figure docs/scaling.md turns into the number of nodes one head can feed.

``pytest -m perf -s tests/perf/test_ray_served.py``; knobs ``MOLMO_PERF_EPISODES`` (8),
``MOLMO_PERF_HORIZON`` (30 steps), ``MOLMO_PERF_HEAD_EPISODES`` (4,12). Rows are appended to
``runs/perf.jsonl``.
"""

from __future__ import annotations

import json
import os
import pickle
import resource
import time
from pathlib import Path

import pytest

pytest.importorskip("torch")
from perf_rows import append_rows, run_rates
from test_lerobot_policy import save_tiny_act

from molmo_lerobot.config import compose
from molmo_lerobot.runner.evaluate import run_evaluation

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


def _dataset_bytes(out: Path, episodes: int) -> int | None:
    """Bytes of the recorded dataset per episode (what workers write to the shared output directory)."""
    root = out / "dataset"
    if not root.is_dir():
        return None
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file()) // episodes


def _bytes_per_episode(cfg, res) -> tuple[int, int]:
    """Pickled size of an episode's plan (head → worker) and of its result (worker → head)."""
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.run_config import RunConfig
    from molmo_lerobot.runner.episode_files import benchmark_path
    from molmo_lerobot.runner.plan import EpisodePlanner

    plain = RunConfig.of(cfg).plain()
    ctx = RunContext.build(plain)
    planner = EpisodePlanner(ctx, load_benchmark(benchmark_path(plain["benchmark"], ctx.plugins), ctx.plugins))
    plan = max(len(pickle.dumps(planner.plan(e.episode_index))) for e in res.episodes)
    result = max(len(pickle.dumps(e.to_dict())) for e in res.episodes)
    return plan, result


@pytest.fixture(scope="module")
def two_nodes():
    """A two-node cluster on this machine (one CPU each), joined by this process; its start-up seconds."""
    import ray
    from ray.cluster_utils import Cluster

    t0 = time.perf_counter()
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="WARNING")
    try:
        yield time.perf_counter() - t0
    finally:
        ray.shutdown()
        cluster.shutdown()


def _act_run(act: str, out: Path, workers: int, limit: int, *extra: str):
    return compose(["policy=lerobot", f"policy.path={act}", "policy.device=cpu", "policy.mode=chunk",
                    "+policy.cameras.exterior=observation.images.front", "benchmark=pick_v1", f"limit={limit}",
                    f"horizon={HORIZON}", f"workers={workers}", f"output_dir={out}", "progress=false", *extra])


def test_ray_per_node_servers_vs_one_box(two_nodes, tmp_path):
    act = save_tiny_act(tmp_path / "act", image_hw=(224, 224))
    cluster_s = two_nodes
    run_evaluation(_act_run(act, tmp_path / "warm-up", 1, 1))  # the head's first-run imports counted nowhere
    rows, outcomes, sizes = [], {}, None
    for mode, (workers, extra) in MODES.items():
        out = tmp_path / mode.replace(" ", "_")
        cfg = _act_run(act, out, workers, EPISODES, *extra)
        cpu0 = _cpu_self()
        res = run_evaluation(cfg)
        head_cpu = _cpu_self() - cpu0
        outcomes[mode] = [(e.episode_index, e.success, e.success_once, e.steps, e.error) for e in res.episodes]
        row, stats = run_rates(res, workers, out)
        per_node = ({nid[:8]: {"served": s["served"], "batch_sizes": s["batch_sizes"]}
                     for nid, s in stats["nodes"].items()} if "nodes" in stats else None)
        rows.append({"mode": mode, **row, "head_cpu_ms_per_episode": round(1000 * head_cpu / len(res.episodes), 1),
                     "dataset_bytes_per_episode": _dataset_bytes(out, len(res.episodes)),
                     "batch_sizes": stats.get("batch_sizes"), "per_node": per_node})
        if sizes is None:
            sizes = _bytes_per_episode(cfg, res)
    base = rows[0]["eps_per_min"]
    print(f"\ntiny ACT on pick_v1, {EPISODES} episodes x {HORIZON} steps, CPU; 2-node local cluster started in "
          f"{cluster_s:.1f} s; per episode {sizes[0]} B plan to the worker, {sizes[1]} B result back")
    print(f"{'mode':>21} {'workers':>7} {'wall s':>7} {'eps/min':>8} {'excl. start':>11} {'vs base':>7} "
          f"{'head ms/ep':>10}  batch sizes / per node")
    for r in rows:
        print(f"{r['mode']:>21} {r['workers']:>7} {r['wall_s']:>7.1f} {r['eps_per_min']:>8.2f} "
              f"{r['eps_per_min_excl_startup'] or 0:>11.2f} {r['eps_per_min'] / base:>7.2f} "
              f"{r['head_cpu_ms_per_episode']:>10.1f}  {r['per_node'] or r['batch_sizes'] or '-'}")
    append_rows("ray_served", rows, horizon=HORIZON, cluster_start_s=round(cluster_s, 2), bytes_to_workers=sizes[0],
                bytes_from_workers=sizes[1])
    reference = outcomes["local in-process"]
    assert all(o == reference for o in outcomes.values()), "per-episode outcomes differ between modes"
    assert all(r["errors"] == 0 for r in rows)
    two = next(r for r in rows if r["mode"] == "ray 2 nodes")
    assert len(two["per_node"]) == 2 and all(n["served"] > 0 for n in two["per_node"].values())


def test_head_cost_per_episode(two_nodes, tmp_path):
    """The head's marginal CPU per episode, ``(cpu(N) - cpu(M)) / (N - M)`` for M and N episodes
    (``MOLMO_PERF_HEAD_EPISODES``, 4,12) of ``ray 2 nodes`` with the random policy served, without
    and with recording: where one head core saturates (docs/scaling.md)."""
    m, n = (int(k) for k in os.environ.get("MOLMO_PERF_HEAD_EPISODES", "4,12").split(","))

    def head_cpu(out: Path, limit: int, *extra: str) -> float:
        cfg = compose(["policy=random", "benchmark=pick_v1", f"limit={limit}", f"horizon={HORIZON}", "workers=2",
                       "executor=ray", "+policy.serve=true", f"output_dir={out}", "progress=false", *extra])
        cpu0 = _cpu_self()
        res = run_evaluation(cfg)
        assert res.summary["n_errors"] == 0
        return _cpu_self() - cpu0

    head_cpu(tmp_path / "warm-up", 1, "record=true")
    rows = []
    for record in (False, True):
        cpus = {k: head_cpu(tmp_path / f"r{int(record)}-{k}", k, f"record={str(record).lower()}") for k in (m, n)}
        per = (cpus[n] - cpus[m]) / (n - m)
        rows.append({"record": record, "episodes": [m, n], "head_cpu_s": [round(cpus[m], 2), round(cpus[n], 2)],
                     "head_cpu_ms_per_episode": round(1000 * per, 1),
                     "head_fixed_cpu_s": round(cpus[m] - m * per, 2),
                     "head_saturates_eps_per_min": round(60 / per) if per > 0 else None})
    print(f"\nhead CPU per episode, ray 2 nodes, random policy served, {HORIZON} steps:")
    for r in rows:
        print(json.dumps(r))
    append_rows("ray_served_head_cost", rows, horizon=HORIZON)
