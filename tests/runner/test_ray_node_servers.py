"""``executor=ray policy.serve=true``: one policy server per Ray node, each node's workers its clients.

The end-to-end test runs on a two-node cluster on this machine (``ray.cluster_utils.Cluster``:
two raylets, one of them declaring a GPU), so routing by node is real: each node's simulator
actor must reach its own node's server, and the server on the "GPU" node must hold its GPU.
"""

from __future__ import annotations

import json

import pytest

from molmo_lerobot.errors import RunError
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.serving.ray_servers import server_nodes
from molmo_lerobot.serving.run_server import STATS_FILE

HORIZON = 10  # the random policy answers chunks of 8 steps: 2 requests per episode


@pytest.fixture
def two_nodes():
    """A head and a second node with one CPU each (the second declares one GPU), joined by this process."""
    import ray
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    cluster.add_node(num_cpus=1, num_gpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="WARNING")
    try:
        yield cluster
    finally:
        ray.shutdown()
        cluster.shutdown()


def test_server_nodes_are_the_alive_nodes_with_room_for_a_worker():
    nodes = [{"NodeID": "a", "Alive": True, "Resources": {"CPU": 4.0, "GPU": 1.0}},
             {"NodeID": "b", "Alive": True, "Resources": {"CPU": 0.0}},  # a head that runs no workers
             {"NodeID": "c", "Alive": False, "Resources": {"CPU": 8.0}},
             {"NodeID": "d", "Alive": True, "Resources": {"CPU": 2.0}}]
    assert [n["NodeID"] for n in server_nodes(nodes, 1.0, 0.0)] == ["a", "d"]
    assert [n["NodeID"] for n in server_nodes(nodes, 1.0, 0.5)] == ["a"]


def test_each_node_serves_its_own_workers_and_outcomes_equal_in_process(two_nodes, small_bench, tmp_path,
                                                                       eval_config, outcomes):
    common = ["policy=random", f"horizon={HORIZON}", "limit=2"]  # one episode for each worker
    run_evaluation(eval_config(small_bench, tmp_path / "local", *common, "workers=1"))
    served = run_evaluation(eval_config(small_bench, tmp_path / "ray", *common, "workers=2", "executor=ray",
                                        "+policy.serve=true"))
    assert outcomes(tmp_path / "ray") == outcomes(tmp_path / "local")
    assert served.summary["n_errors"] == 0 and len(outcomes(tmp_path / "local")) == 2
    stats = json.loads((tmp_path / "ray" / STATS_FILE).read_text())
    nodes = stats["nodes"]
    assert stats["servers"] == len(nodes) == 2 and stats["servers_died"] == 0
    # one worker per node (one CPU each), one episode each: each server answered its own node's worker only
    assert [n["served"] for n in nodes.values()] == [2, 2] and stats["served"] == 2 * 2
    assert sorted((n["num_gpus"], n["gpu_ids"]) for n in nodes.values()) == [(0, []), (1, ["0"])]
    # (not their open connections: an ended actor's connection closes asynchronously, and the statistics may
    # be read before its server has seen that, as under the load of a parallel test run)
    assert all(n["alive"] for n in nodes.values())


@pytest.mark.slow
def test_a_server_that_dies_makes_infrastructure_errors_that_resume_reruns(faulty_policy, small_bench, tmp_path,
                                                                           eval_config, outcomes):
    """The served policy SIGKILLs its server (the actor's process) at episode 1's first action: every
    episode of that node from then on fails as an infrastructure error; once fixed, a resume runs
    them again and the run equals an uninterrupted one."""
    markers = faulty_policy.marker_dir
    common = ["policy=faulty", "horizon=2", "limit=4", "+policy.faults={1: sigkill_until_fixed}",
              f"policy.marker_dir={markers}", "workers=2", "executor=ray", "+policy.serve=true"]
    (markers / "fixed").touch()
    run_evaluation(eval_config(small_bench, tmp_path / "ref", *common))
    (markers / "fixed").unlink()

    out = tmp_path / "run"
    broken = run_evaluation(eval_config(small_bench, out, *common))
    by = {r.episode_index: r for r in broken.episodes}
    assert by[1].error_kind == "infrastructure" and "policy server ws://127.0.0.1:" in by[1].error, by[1].error
    assert all(r.error is None or r.error_kind == "infrastructure" for r in broken.episodes)
    stats = json.loads((out / STATS_FILE).read_text())
    assert stats["servers"] == 1 and stats["servers_died"] == 1
    assert next(iter(stats["nodes"].values()))["alive"] is False

    (markers / "fixed").touch()
    resumed = run_evaluation(eval_config(small_bench, out, *common, "resume=true"))
    assert resumed.summary["n_errors"] == 0 and outcomes(out) == outcomes(tmp_path / "ref")


@pytest.mark.slow
def test_a_node_server_that_cannot_start_fails_the_run_with_one_line(faulty_policy, small_bench, tmp_path,
                                                                      eval_config):
    import ray

    cfg = eval_config(small_bench, tmp_path / "run", "policy=faulty", "policy.fail_init=true", "executor=ray",
                      "+policy.serve=true", "workers=1", "limit=1")
    with pytest.raises(RunError, match=r"^policy.serve: the policy server on node \w+ \(.*\) did not start: "
                                       r"RuntimeError: .*refusing to start"):
        run_evaluation(cfg)
    assert not ray.is_initialized(), "the executor shuts down the cluster it started"
    assert not (tmp_path / "run" / "results.json").exists()
