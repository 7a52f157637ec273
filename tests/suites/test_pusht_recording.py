"""``record=true`` on a PushT run: the dataset has ``lerobot/pusht``'s layout, loads in ``LeRobotDataset``, and
LeRobot's own ``aggregate_datasets`` merges it with a dataset in that layout written by LeRobot's own
``LeRobotDataset.create`` + ``add_frame`` (the stand-in for ``lerobot/pusht``, which cannot be downloaded here).
The default test plays gym_pusht's real env through the rollout loop and the run's recorder in this process; the
``slow`` one records a ``molmo-eval`` run (a worker's start costs ~a minute on this loaded machine)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import standin_dataset

from molmo_lerobot.benchmark_kinds import run_kind
from molmo_lerobot.config import compose
from molmo_lerobot.export.merge import read_eval_records
from molmo_lerobot.export.recorder import LeRobotRecorderFactory
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import Policy
from molmo_lerobot.results import summarize
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.suites import pusht
from molmo_lerobot.suites.benchmark import SuiteSession, suite_plan
from molmo_lerobot.suites.plugin import PUSHT
from molmo_lerobot.suites.pusht import PushTSuite

#: ``lerobot/pusht``'s features as LeRobot's own code wrote them (``pusht_zarr_format`` at codebase v1.6, carried to
#: v2.0 by ``convert_dataset_v1_to_v2`` without a robot config), fps 10, robot ``unknown``. Written out here, not
#: imported from the code under test, so that a drift of ours fails.
MOTORS = {"motors": ["motor_0", "motor_1"]}
THEIR_FEATURES = {
    "observation.image": {"dtype": "video", "shape": (96, 96, 3), "names": ["height", "width", "channel"]},
    "observation.state": {"dtype": "float32", "shape": (2,), "names": MOTORS},
    "action": {"dtype": "float32", "shape": (2,), "names": MOTORS},
    "next.reward": {"dtype": "float32", "shape": (1,), "names": None},
    "next.success": {"dtype": "bool", "shape": (1,), "names": None},
    "next.done": {"dtype": "bool", "shape": (1,), "names": None},
}
THEIR_FPS, THEIR_ROBOT = 10, "unknown"
THEIR_TASK = "Push the T-shaped block onto the T-shaped target."


def write_standin(root, episodes: int, frames: int):
    """A small dataset in ``lerobot/pusht``'s layout, written by LeRobot's own writer."""

    def frame(rng, i):
        return {"observation.image": rng.integers(0, 255, (96, 96, 3), dtype=np.uint8),
                "observation.state": rng.uniform(0, 512, 2).astype(np.float32),
                "action": rng.uniform(0, 512, 2).astype(np.float32),
                "next.reward": np.array([0.1], np.float32), "next.success": np.array([False]),
                "next.done": np.array([i == frames - 1]), "task": THEIR_TASK}

    return standin_dataset.write_standin(root, "standin/pusht", THEIR_FEATURES, THEIR_FPS, THEIR_ROBOT, episodes,
                                         frames, frame, seed=3)


def assert_pusht_layout(root) -> None:
    """``meta/info.json`` of a recording: exactly ``lerobot/pusht``'s features, fps and robot type."""
    info = json.loads((root / "meta/info.json").read_text())
    own = {k: {f: v[f] for f in ("dtype", "shape", "names")} for k, v in info["features"].items()
           if k not in ("timestamp", "frame_index", "episode_index", "index", "task_index")}
    assert own == {k: {**v, "shape": list(v["shape"])} for k, v in THEIR_FEATURES.items()}
    assert (info["fps"], info["robot_type"]) == (THEIR_FPS, THEIR_ROBOT)


def merge_with_standin(ours, tmp_path):
    """LeRobot's aggregate of ``ours`` and a one-episode, three-frame stand-in; the merged ``LeRobotDataset``."""
    from lerobot.datasets.aggregate import aggregate_datasets
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    theirs = write_standin(tmp_path / "standin", episodes=1, frames=3)
    aggregate_datasets(["ours/pusht", "standin/pusht"], "merged/pusht", roots=[ours, theirs],
                       aggr_root=tmp_path / "merged")
    return LeRobotDataset("merged/pusht", root=tmp_path / "merged", video_backend="pyav")


class Sweep(Policy):
    """Targets across the workspace, one per step."""

    def reset(self, ctx) -> None:
        self.t = 0

    def act(self, obs) -> dict:
        self.t += 1
        return {"agent": np.array([40.0 * self.t, 300.0], np.float32)}


def test_a_pusht_recording_has_lerobots_pusht_layout_and_merges_with_theirs(tmp_path):
    """Episodes of gym_pusht's real env through the one rollout loop, a ``SuiteSession`` and the run's recorder
    (what a ``benchmark=pusht record=true`` worker does, without starting one)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    config = compose(["policy=random", "benchmark=pusht", "record=true", "horizon=5", f"output_dir={tmp_path / 'run'}"])
    run = RunConfig.of(config)
    factory = LeRobotRecorderFactory.from_config(run, run_kind(Plugins(), run).recording_layout(run))
    out = tmp_path / "run"
    recorder = factory.make("w0", out)
    suite = PushTSuite()
    episodes = pusht.plan_episodes("pusht", suite.tasks("pusht"), 2, seed=0, horizon=5)
    results, seen = [], []
    try:
        for i, episode in enumerate(episodes):
            plan = suite_plan(i, PUSHT, episode, False)
            session = SuiteSession(PUSHT, plan, suite, pusht.IMAGE_SIZE, end_on_success=True)
            seen.append(session.observe()["qpos"]["agent"].copy())
            policy = Sweep()
            policy.reset(session.policy_context())
            recorder.start_episode(session.recorder_info(expert=False, extra={}))
            results.append(rollout(session, policy, [recorder], "sweep"))
            recorder.end_episode(results[-1])
    finally:
        suite.close()
    recorder.close()
    summary = summarize(results, benchmark={"name": "pusht", "sha256": "ab" * 32, "n_episodes": 2},
                        policy={"name": "sweep"}, seed=0)
    factory.finalize(out, results, summary)

    root = out / "dataset"
    assert_pusht_layout(root)
    assert json.loads((root / "meta/eval/info.json").read_text())["fps_exact"] == 10.0  # PushT's control rate
    ds = LeRobotDataset(factory.repo_id, root=root, video_backend="pyav")
    assert (ds.meta.total_episodes, ds.meta.total_frames) == (2, 10)
    frames = [ds[i] for i in range(10)]
    assert [bool(f["next.done"]) for f in frames] == [False] * 4 + [True] + [False] * 4 + [True]
    assert not any(bool(f["next.success"]) for f in frames)  # five steps never push the T home
    assert all(0.0 <= float(f["next.reward"]) <= 1.0 for f in frames)
    assert np.array_equal(frames[0]["observation.state"].numpy(), seen[0])  # the agent where the policy saw it
    assert np.array_equal(frames[5]["observation.state"].numpy(), seen[1])
    assert np.array_equal(frames[6]["action"].numpy(), [80.0, 300.0])  # frame i: the action taken on obs i
    assert tuple(frames[0]["observation.image"].shape) == (3, 96, 96)
    records = read_eval_records(root)
    assert [(r["episode_index"], r["steps"], r["frames"], r["seed"]) for r in records] == [(0, 5, 5, 0), (1, 5, 5, 1)]

    card = (root / "README.md").read_text()
    assert "joint" not in card and "MuJoCo" not in card and "pymunk" in card
    for said in ("Robot: `unknown`", "`observation.state` (float32 2): the agent's 2-D position",
                 "`action` (float32 2): the agent's 2-D target position", "`next.reward` (float32 1)",
                 "1 simulated RGB camera(s), `observation.image` (96x96), at 10 fps",
                 "the episodes have no language instruction; their LeRobot task is the task's name"):
        assert said in card, said

    merged = merge_with_standin(root, tmp_path)
    assert (merged.meta.total_episodes, merged.meta.total_frames) == (3, 13)
    assert merged[12]["task"] == THEIR_TASK and bool(merged[12]["next.done"])
    assert np.array_equal(merged[6]["action"].numpy(), [80.0, 300.0])


@pytest.mark.slow
def test_a_recorded_pusht_run_merges_with_lerobots_pusht_layout(tmp_path):
    """``molmo-eval policy=random benchmark=pusht record=true``: the same through a worker (~70 s here)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from molmo_lerobot.runner.evaluate import run_evaluation

    out = tmp_path / "run"
    res = run_evaluation(compose(["policy=random", "benchmark=pusht", "workers=1", "horizon=5", "limit=2",
                                  "record=true", "progress=false", f"output_dir={out}"]))
    assert [(r.error, r.steps) for r in res.episodes] == [(None, 5), (None, 5)]
    root = out / "dataset"
    assert_pusht_layout(root)
    ds = LeRobotDataset("local/x", root=root, video_backend="pyav")
    assert (ds.meta.total_episodes, ds.meta.total_frames) == (2, 10)
    assert all(0 <= float(v) <= 512 for i in range(10) for v in ds[i]["action"])  # random targets in the workspace
    merged = merge_with_standin(root, tmp_path)
    assert (merged.meta.total_episodes, merged.meta.total_frames) == (3, 13)
