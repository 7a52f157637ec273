"""``molmo-eval … policy=lerobot policy.serve=true`` (issue 17 item 2): one local server for the run,
every worker its client; the run's results equal in-process evaluation for a deterministic policy
(the seeded random policy in the default run; a tiny random-init ACT reading the exterior camera, batched,
``slow``), over websockets and over shared memory (issue 28 item 2)."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import signal
import threading
import time

import numpy as np
import pytest

pytest.importorskip("torch")
from test_lerobot_policy import save_tiny_act

from molmo_lerobot.config import compose
from molmo_lerobot.errors import RunError
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.serving.run_server import STATS_FILE

HORIZON = 8


@pytest.fixture(scope="module")
def act_dir(tmp_path_factory):
    return save_tiny_act(tmp_path_factory.mktemp("act"), image_hw=(56, 56))


def evaluate(act_dir, out, *overrides):
    cfg = compose(["policy=lerobot", f"policy.path={act_dir}", "policy.device=cpu",
                   "+policy.cameras.exterior=observation.images.front", "benchmark=pick_v1", "limit=2",
                   f"horizon={HORIZON}", "seed=3", f"output_dir={out}", "progress=false", "record=true", *overrides])
    return run_evaluation(cfg)


def actions(run) -> np.ndarray:
    """Recorded actions, in benchmark episode order (workers finish episodes in any order)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = run.output_dir / "dataset"
    bench_index = {r["episode_index"]: r["benchmark_episode_index"]
                   for r in map(json.loads, (root / "meta" / "eval" / "episodes.jsonl").read_text().splitlines())}
    ds = LeRobotDataset(json.loads((root / "meta" / "info.json").read_text()).get("repo_id", "local/x"), root=root)
    rows = sorted((bench_index[int(r["episode_index"])], int(r["frame_index"]), np.asarray(r["action"]))
                  for r in ds.hf_dataset)
    return np.stack([a for _, _, a in rows])


def outcome(e) -> tuple:
    return (e.episode_index, e.success, e.success_once, e.steps, e.seed, e.error)


def test_a_served_run_over_shared_memory_gives_the_in_process_outcomes(tmp_path, fork_servers):
    """``policy.serve=true`` with the local executor: one server over shared memory (``auto``), two workers its
    clients; per episode the outcomes of the policy in process (the seeded random policy: no LeRobot import,
    the batched ACT runs below are ``slow``; batching itself is tests/protocol/test_batching.py)."""
    def run(out, *overrides):
        return run_evaluation(compose(["policy=random", "benchmark=pick_v1", "limit=2", f"horizon={HORIZON}",
                                       "seed=3", f"output_dir={out}", "progress=false", *overrides]), fork_servers)

    local = run(tmp_path / "local", "workers=1")
    served = run(tmp_path / "served", "workers=2", "+policy.serve=true")
    assert served.summary["n_errors"] == 0 and served.summary["policy"]["serve"] is True
    assert [outcome(e) for e in served.episodes] == [outcome(e) for e in local.episodes]
    stats = json.loads((tmp_path / "served" / STATS_FILE).read_text())
    assert stats["transport"] == "shm" and stats["served"] > 0 and not stats["batching"]
    assert not mp.active_children()  # the server process was stopped and reaped


# websockets: served runs over them stay in the default run through tests/protocol/test_remote_policy.py
@pytest.mark.slow
@pytest.mark.parametrize("transport", ["websocket", "auto"])
def test_served_batched_runs_equal_in_process_over_both_transports(act_dir, tmp_path, transport):
    """In process, served over websockets and served over shared memory (``auto`` on Linux): the
    same outcomes per episode, the same actions up to batched rounding."""
    local = evaluate(act_dir, tmp_path / "local", "workers=1")
    assert local.summary["n_errors"] == 0 and len(local.episodes) == 2
    out = tmp_path / transport
    batched = evaluate(act_dir, out, "workers=2", "policy.serve=true", "policy.serve_batch_timeout_ms=50",
                       f"policy.serve_transport={transport}")
    assert [outcome(e) for e in batched.episodes] == [outcome(e) for e in local.episodes], transport
    assert batched.summary["policy"]["name"] == "lerobot" and batched.summary["policy"]["serve"] is True
    stats = json.loads((out / STATS_FILE).read_text())
    assert stats["transport"] == {"websocket": "websocket", "auto": "shm"}[transport]
    assert stats["batching"] and stats["max_batch"] == 2 and stats["served"] > 0
    # one forward for several workers' requests rounds differently from one per request (float32), and
    # which requests share a forward depends on timing; the difference compounds over the steps
    np.testing.assert_allclose(actions(batched), actions(local), rtol=1e-3, atol=2e-4)
    assert not mp.active_children()  # the server process was stopped and reaped


@pytest.mark.slow
def test_served_unbatched_run_is_bit_identical_to_in_process(act_dir, tmp_path):
    local = evaluate(act_dir, tmp_path / "local", "workers=1", "limit=3")
    for transport in ("websocket", "shm"):
        served = evaluate(act_dir, tmp_path / transport, "workers=3", "limit=3", "policy.serve=true",
                          "policy.serve_max_batch=1", f"policy.serve_transport={transport}")
        assert [outcome(e) for e in served.episodes] == [outcome(e) for e in local.episodes]
        np.testing.assert_array_equal(actions(served), actions(local))


@pytest.mark.slow
def test_a_killed_shm_server_costs_infrastructure_errors_that_resume_reruns(act_dir, tmp_path):
    """kill -9 of the run's server once an episode is recorded: the episodes it leaves are
    infrastructure errors of one line; ``resume=true`` (a new server) gives the in-process outcomes."""
    local = evaluate(act_dir, tmp_path / "local", "workers=1", "limit=3")
    out, killed = tmp_path / "shm", threading.Event()

    def kill_the_server_after_an_episode() -> None:
        deadline = time.monotonic() + 600
        while not killed.is_set() and time.monotonic() < deadline:
            if (out / "episodes.jsonl").exists() and (out / "episodes.jsonl").read_text().strip():
                for proc in mp.active_children():
                    if proc.name == "molmo-serve":
                        os.kill(proc.pid, signal.SIGKILL)
                        killed.set()
            time.sleep(0.02)

    killer = threading.Thread(target=kill_the_server_after_an_episode, daemon=True)
    killer.start()
    evaluate(act_dir, out, "workers=1", "limit=3", "policy.serve=true", "policy.serve_transport=shm")
    killed.set()
    killer.join()
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    lost = [r for r in rows if r["error"]]
    assert lost and all(r["error_kind"] == "infrastructure" and "\n" not in r["error"] for r in lost)
    assert not (out / STATS_FILE).exists()  # the killed server sent no statistics
    resumed = evaluate(act_dir, out, "workers=1", "limit=3", "policy.serve=true", "policy.serve_transport=shm",
                       "resume=true")
    assert [outcome(e) for e in resumed.episodes] == [outcome(e) for e in local.episodes]


def test_a_server_that_cannot_start_fails_the_run_with_one_line(tmp_path, fork_servers):
    """The server cannot build its policy (replay's actions file is missing: no LeRobot import to wait for)."""
    cfg = compose(["policy=replay", f"policy.actions={tmp_path}/missing.npy", "+policy.serve=true",
                   "benchmark=pick_v1", "limit=1", f"output_dir={tmp_path / 'run'}", "progress=false"])
    with pytest.raises(RunError) as err:
        run_evaluation(cfg, fork_servers)
    assert str(err.value).startswith("policy.serve: the policy server did not start: ValueError: policy.actions=")
    assert "cannot load a .npy array" in str(err.value) and "\n" not in str(err.value)
