"""``molmo-eval benchmark=metaworld_*``: LeRobot's MetaWorld episodes through our workers, results, recording and
MetaWorld's scripted experts (``policy=scripted``).

MetaWorld runs in the worker's own process; a step costs well under a millisecond and a 480² frame ~0.25 s on this
machine's software GL, so these runs play short episodes at a small image size (the parity tests use LeRobot's 480²).
"""

from __future__ import annotations

import json

import pytest

from molmo_lerobot.benchmark_kinds import BenchmarkKindError, run_kind
from molmo_lerobot.config import compose
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.suites import metaworld
from molmo_lerobot.suites.benchmark import plan_problems

pytest.importorskip("metaworld")

#: ``lerobot/metaworld_mt50``'s features as its published ``meta/info.json`` has them (those a recording here
#: carries; written out, not imported from the code under test), fps 80, robot ``metaworld``
THEIR_FEATURES = {
    "observation.state": {"dtype": "float32", "shape": [4], "names": {"axes": None}},
    "action": {"dtype": "float32", "shape": [4], "names": {"axes": ["x", "y", "z", "gripper"]}},
    "next.reward": {"dtype": "float32", "shape": [1], "names": None},
    "next.success": {"dtype": "bool", "shape": [1], "names": None},
}


def test_random_run_with_two_workers_scores_per_task_and_records_a_lerobot_dataset(tmp_path):
    """``molmo-eval policy=random benchmark=metaworld_hard benchmark.episodes_per_task=1 workers=2 limit=2
    record=true``: one episode of each of the group's first two tasks, scored per task, recorded."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    run_evaluation(compose(["policy=random", "benchmark=metaworld_hard", "benchmark.episodes_per_task=1",
                            "benchmark.image_size=64", "horizon=8", "workers=2", "limit=2", "record=true",
                            "progress=false", f"output_dir={tmp_path}"]))
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["n_episodes"] == 2 and doc["n_errors"] == 0
    assert list(doc["per_task"]) == ["metaworld/assembly-v3", "metaworld/hand-insert-v3"]
    assert doc["per_task"]["metaworld/assembly-v3"]["instructions"] == ["Pick up a nut and place it onto a peg"]
    lines = sorted((json.loads(line) for line in (tmp_path / "episodes.jsonl").read_text().splitlines()),
                   key=lambda e: e["episode_index"])
    assert [(e["seed"], e["steps"], e["extra"]["group"], e["extra"]["task_id"], e["error"]) for e in lines] == [
        (0, 8, "hard", 0, None), (0, 8, "hard", 1, None)]
    info = json.loads((tmp_path / "eval_info.json").read_text())
    assert [(t["task_group"], t["task_id"]) for t in info["per_task"]] == [("metaworld_hard", 0),
                                                                          ("metaworld_hard", 1)]
    ds = LeRobotDataset("local/x", root=tmp_path / "dataset", video_backend="pyav")
    assert ds.meta.total_episodes == 2 and ds.meta.total_frames == 16
    assert (ds.meta.fps, ds.meta.robot_type) == (metaworld.CONTROL_HZ, "metaworld")
    features = ds.meta.features
    assert {k: {"dtype": features[k]["dtype"], "shape": list(features[k]["shape"]), "names": features[k]["names"]}
            for k in THEIR_FEATURES} == THEIR_FEATURES
    assert tuple(features["observation.image"]["shape"]) == (64, 64, 3)
    frame = ds[0]
    assert tuple(frame["observation.image"].shape) == (3, 64, 64) and frame["task"] == lines[0]["prompt"]


def test_scripted_plays_metaworld_s_expert_of_each_task(tmp_path):
    """``policy=scripted`` on a MetaWorld benchmark plays MetaWorld's expert of each episode's task."""
    res = run_evaluation(compose(["policy=scripted", "benchmark=metaworld_reach-v3", "benchmark.episodes_per_task=2",
                                  "workers=1", "progress=false", f"output_dir={tmp_path}"]))
    assert res.run_summary.n_episodes == 2
    lines = [json.loads(line) for line in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    assert all(e["success"] and e["error"] is None and e["extra"]["ended_by"] == "success" for e in lines), lines
    assert all(e["steps"] < 100 for e in lines)


def test_benchmarks_mirror_lerobot_eval_s_env_task_values():
    """``metaworld_<group>``, ``metaworld_mt50`` (the four groups in order) and ``metaworld_<task>`` plan LeRobot's
    tasks with its per-group task ids; a horizon past MetaWorld's 500 steps is refused up front."""

    def planned(*overrides: str):
        config = RunConfig.of(compose(["policy=random", *overrides]))
        return run_kind(Plugins(), config).benchmark_of(config)

    mt50 = planned("benchmark=metaworld_mt50", "benchmark.episodes_per_task=1")
    assert len(mt50.episodes) == 50 and [e.group for e in mt50.episodes][::10] == [
        "easy", "easy", "easy", "medium", "hard"]
    [reach] = planned("benchmark=metaworld_reach-v3", "benchmark.episodes_per_task=1").episodes
    assert (reach.group, reach.task_id, reach.task, reach.horizon) == ("reach-v3", 0, "reach-v3", 500)
    very_hard = planned("benchmark=metaworld_very_hard", "benchmark.episodes_per_task=2", "seed=7")
    assert [(e.task_id, e.seed) for e in very_hard.episodes][:3] == [(0, 7), (0, 8), (1, 7)]
    with pytest.raises(BenchmarkKindError):
        planned("benchmark=metaworld_easy", "+benchmark.hard_reset=false")
    long = planned("benchmark=metaworld_reach-v3", "benchmark.episodes_per_task=1", "horizon=501")
    assert plan_problems(long, metaworld.catalogue("metaworld_reach-v3")) == [
        "metaworld_reach-v3 episode 0: horizon 501: MetaWorld plays at most 500 steps"]


def test_an_episode_plays_the_same_whatever_the_worker_s_env_played_before():
    """A worker keeps its task's env across episodes, in whatever order the run hands it seeds (``lerobot-eval``
    plays them in order on one env): the seeded reset leaves nothing of the episode before."""
    import numpy as np

    from molmo_lerobot.suites.metaworld import MetaWorldEpisode, MetaWorldSuite

    def play(suite: MetaWorldSuite, seed: int, steps: int) -> list:
        first = suite.reset(MetaWorldEpisode("metaworld_push-v3", "push-v3", 0, "push-v3", seed, steps, ""))
        out, rng = [suite.raw_observation.tolist(), first["observation.image"].tolist()], np.random.default_rng(seed)
        for _ in range(steps):
            reply = suite.step(rng.uniform(-1, 1, 4), images=False)
            out.append((suite.raw_observation.tolist(), reply["reward"], reply["success"]))
        return out

    fresh, used = MetaWorldSuite(image_size=32), MetaWorldSuite(image_size=32)
    try:
        play(used, 3, 60)
        assert play(used, 5, 30) == play(fresh, 5, 30)
    finally:
        fresh.close()
        used.close()
