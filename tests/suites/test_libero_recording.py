"""``record=true`` on a LIBERO run: the dataset has the layout of LeRobot's LIBERO datasets, loads in
``LeRobotDataset``, and LeRobot's own ``aggregate_datasets`` merges it with a dataset in that layout written by
LeRobot's own ``LeRobotDataset.create`` + ``add_frame`` (the stand-in for their published dataset, which cannot
be downloaded here).

The default test plays the episodes through the one rollout loop, a real ``SuiteSession`` and the run's
recorder, over a stand-in for the LIBERO process (LIBERO itself costs ~30 s per episode here); the ``slow``
test records a real LIBERO run with ``molmo-eval`` and merges that.
"""

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
from molmo_lerobot.suites.benchmark import SuiteSession, suite_plan
from molmo_lerobot.suites.libero import LiberoEpisode, libero_venv
from molmo_lerobot.suites.plugin import LIBERO

#: LeRobot's LIBERO layout as published (``HuggingFaceVLA/libero`` ``meta/info.json``, codebase v3.0: names,
#: dtypes, shapes, fps 10, robot ``panda``), the cameras as video as ``lerobot/libero`` stores them. Written out
#: here, not imported from the code under test, so that a drift of ours fails.
THEIR_FEATURES = {
    "observation.images.image": {"dtype": "video", "shape": (256, 256, 3), "names": ["height", "width", "channel"]},
    "observation.images.image2": {"dtype": "video", "shape": (256, 256, 3), "names": ["height", "width", "channel"]},
    "observation.state": {"dtype": "float32", "shape": (8,), "names": ["state"]},
    "action": {"dtype": "float32", "shape": (7,), "names": ["actions"]},
}
THEIR_FPS, THEIR_ROBOT = 10, "panda"
SIZE = 256


def write_standin(root, episodes: int, frames: int):
    """A small dataset in LeRobot's LIBERO layout, written by LeRobot's own writer."""

    def frame(rng, i):
        return {"observation.images.image": rng.integers(0, 255, (256, 256, 3), dtype=np.uint8),
                "observation.images.image2": rng.integers(0, 255, (256, 256, 3), dtype=np.uint8),
                "observation.state": rng.normal(size=8).astype(np.float32),
                "action": rng.uniform(-1, 1, 7).astype(np.float32),
                "task": "put the cream cheese in the bowl"}

    return standin_dataset.write_standin(root, "standin/libero", THEIR_FEATURES, THEIR_FPS, THEIR_ROBOT, episodes,
                                         frames, frame, seed=7)


def merge_with_standin(ours, tmp_path, standin_episodes: int = 1, frames: int = 3):
    """LeRobot's aggregate of ``ours`` and a stand-in; the merged ``LeRobotDataset``."""
    from lerobot.datasets.aggregate import aggregate_datasets
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    theirs = write_standin(tmp_path / "standin", standin_episodes, frames)
    aggregate_datasets(["ours/libero", "standin/libero"], "merged/libero", roots=[ours, theirs],
                       aggr_root=tmp_path / "merged")
    return LeRobotDataset("merged/libero", root=tmp_path / "merged", video_backend="pyav")


def assert_libero_layout(info: dict, size: int = SIZE) -> None:
    """``meta/info.json`` of a recording: exactly LeRobot's LIBERO features (at ``size``²), fps and robot."""
    own = {k: {f: v[f] for f in ("dtype", "shape", "names")} for k, v in info["features"].items()
           if k not in ("timestamp", "frame_index", "episode_index", "index", "task_index")}
    expected = {k: {**v, "shape": list(v["shape"])} for k, v in THEIR_FEATURES.items()}
    for key in ("observation.images.image", "observation.images.image2"):
        expected[key]["shape"] = [size, size, 3]
    assert own == expected
    assert (info["fps"], info["robot_type"]) == (THEIR_FPS, THEIR_ROBOT)


class FakeLibero:
    """Stands for the LIBERO process (``LiberoSuite``): LIBERO's observation keys and shapes; images and
    state encode (episode seed, step); the goal holds from step ``success_at`` of the episode with seed 1."""

    success_at = 3

    def reset(self, episode: LiberoEpisode) -> dict:
        self.seed, self.t, self.drawn = episode.seed, 0, [0]
        return self._obs(True)

    def step(self, action: np.ndarray, images: bool = True) -> dict:
        assert action.shape == (7,)
        self.t += 1
        self.drawn += [self.t] * images
        success = self.seed == 1 and self.t > self.success_at
        return {"observation": self._obs(images), "reward": float(success), "success": success,
                "terminated": success}

    def _obs(self, images: bool) -> dict:
        level = (self.seed * 40 + self.t * 9) % 250
        state = {"observation.state": np.arange(8, dtype=np.float32) + 10 * self.seed + self.t}
        if not images:  # as LIBERO's server answers a step asked to draw nothing
            return state
        return {"observation.images.image": np.full((SIZE, SIZE, 3), level, np.uint8),
                "observation.images.image2": np.full((SIZE, SIZE, 3), 255 - level, np.uint8), **state}


class Ramp(Policy):
    def reset(self, ctx) -> None:
        self.t = 0

    def act(self, obs) -> dict:
        self.t += 1
        return {"eef": np.full(7, self.t / 10, np.float32)}


def test_a_suite_recording_has_lerobots_libero_layout_and_merges_with_theirs(tmp_path):
    config = compose(["policy=random", "benchmark=libero_object", "record=true", f"benchmark.image_size={SIZE}",
                      f"output_dir={tmp_path / 'run'}"])
    run = RunConfig.of(config)
    factory = LeRobotRecorderFactory.from_config(run, run_kind(Plugins(), run).recording_layout(run))
    out = tmp_path / "run"
    recorder = factory.make("w0", out)
    episodes = [LiberoEpisode("libero_object", 0, 0, 0, 6, "pick up the soup and place it in the basket"),
                LiberoEpisode("libero_object", 1, 0, 1, 6, "pick up the milk and place it in the basket")]
    results = []
    for i, episode in enumerate(episodes):
        session = SuiteSession(LIBERO, suite_plan(i, LIBERO, episode, True), FakeLibero(), SIZE, end_on_success=True)
        policy = Ramp()
        policy.reset(session.policy_context())
        recorder.start_episode(session.recorder_info(expert=False, extra={}))
        results.append(rollout(session, policy, [recorder], "ramp"))
        recorder.end_episode(results[-1])
    recorder.close()
    assert [(r.steps, r.success) for r in results] == [(6, False), (4, True)]  # LIBERO's goal ends episode 1
    summary = summarize(results, benchmark={"name": "libero_object", "sha256": "ab" * 32, "n_episodes": 2},
                        policy={"name": "ramp"}, seed=0)
    factory.finalize(out, results, summary)

    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = out / "dataset"
    info = json.loads((root / "meta/info.json").read_text())
    assert_libero_layout(info)
    assert json.loads((root / "meta/eval/info.json").read_text())["fps_exact"] == 20.0  # LIBERO's control rate
    ds = LeRobotDataset(factory.repo_id, root=root, video_backend="pyav")
    assert (ds.meta.total_episodes, ds.meta.total_frames) == (2, 10)
    first, last = ds[0], ds[9]
    assert first["task"] == episodes[0].instruction and last["task"] == episodes[1].instruction
    assert np.array_equal(first["observation.state"].numpy(), np.arange(8, dtype=np.float32))  # the step-0 state
    assert np.allclose(last["action"].numpy(), 0.4)  # the 4th action of episode 1 (frame i = action on obs i)
    assert abs(float(first["observation.images.image"].mean()) - 0.0) < 0.02  # video, but the frame it was given
    records = read_eval_records(root)
    assert [(r["episode_index"], r["success"], r["steps"], r["frames"], r["prompt"]) for r in records] == [
        (0, False, 6, 6, episodes[0].instruction), (1, True, 4, 4, episodes[1].instruction)]

    card = (root / "README.md").read_text()
    assert "joint" not in card and "MuJoCo through robosuite" in card
    for said in ("`observation.state` (float32 8): the Panda's 8-D end-effector state: position (3), orientation "
                 "as an axis-angle (3), the two finger positions (2)",
                 "`action` (float32 7): the 7-D delta end-effector command",
                 "`observation.images.image2` (video 256x256x3): the wrist camera"):
        assert said in card, said

    merged = merge_with_standin(root, tmp_path, standin_episodes=1, frames=3)
    assert (merged.meta.total_episodes, merged.meta.total_frames) == (3, 13)
    assert sorted(merged.meta.tasks.index) == sorted(
        [episodes[0].instruction, episodes[1].instruction, "put the cream cheese in the bowl"])
    assert merged[12]["task"] == "put the cream cheese in the bowl" and merged[0]["task"] == episodes[0].instruction


class Chunks(Policy):
    """Chunks of 4 actions (run open loop); asserts it sees the images whenever it is asked to act."""

    def __init__(self, needs_images: bool) -> None:
        self.needs_images, self.asked = needs_images, []

    def reset(self, ctx) -> None:
        self.asked = []

    def act(self, obs) -> dict:
        self.asked.append(obs["step"])
        assert ("images" in obs) == self.needs_images, obs["step"]
        return {"eef": np.zeros((4, 7), np.float32)}


@pytest.mark.parametrize("needs_images", [True, False])
def test_a_suite_step_draws_only_the_frames_someone_reads(needs_images):
    """Not recording, LIBERO draws the frames of the steps where a policy reading images gets an observation
    (a chunk's end) and none for a policy that reads none; the observation of a step without them has none."""
    episode = LiberoEpisode("libero_object", 0, 0, 0, 10, "pick up the soup and place it in the basket")
    env = FakeLibero()
    session = SuiteSession(LIBERO, suite_plan(0, LIBERO, episode, True), env, SIZE, end_on_success=True)
    policy = Chunks(needs_images)
    policy.reset(session.policy_context())
    result = rollout(session, policy, [], "chunks")
    assert result.steps == 10 and policy.asked == [0, 4, 8]
    assert env.drawn == ([0, 4, 8] if needs_images else [0])  # the reset's frames are always drawn
    with pytest.raises(RuntimeError, match="played without them"):
        session.observe(images=True)


def test_a_layout_misfit_names_the_feature(tmp_path):
    from molmo_lerobot.features import FeatureError
    from molmo_lerobot.suites.libero_dataset import libero_layout

    layout = libero_layout(64)
    obs = {"images": {"image": np.zeros((64, 64, 3), np.uint8), "image2": np.zeros((32, 32, 3), np.uint8)},
           "qpos": {"eef": np.zeros(8)}}
    with pytest.raises(FeatureError, match=r"observation.images.image2: got uint8 \(32, 32, 3\), expected"):
        layout.frame(obs, {"eef": np.zeros(7)}, None, False, False, "t", None)
    obs["images"]["image2"] = np.zeros((64, 64, 3), np.uint8)
    with pytest.raises(FeatureError, match="action: 6 values, expected 7"):
        layout.frame(obs, {"eef": np.zeros(6)}, None, False, False, "t", None)


needs_libero = pytest.mark.skipif(not (libero_venv() / "bin" / "python").exists(),
                                  reason=f"no LIBERO venv at {libero_venv()} (make .libero-venv builds it)")


@needs_libero
@pytest.mark.slow
def test_a_recorded_libero_run_merges_with_lerobots_libero_layout(tmp_path):
    """``molmo-eval policy=random benchmark=libero_object record=true benchmark.image_size=256``: real LIBERO
    episodes, recorded, loaded and merged with the stand-in."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from molmo_lerobot.runner.evaluate import run_evaluation

    out = tmp_path / "run"
    res = run_evaluation(compose(["policy=random", "benchmark=libero_object", "workers=1", "horizon=6", "limit=2",
                                  "record=true", f"benchmark.image_size={SIZE}", "progress=false",
                                  f"output_dir={out}"]))
    assert [r.error for r in res.episodes] == [None, None]
    root = out / "dataset"
    assert_libero_layout(json.loads((root / "meta/info.json").read_text()))
    ds = LeRobotDataset("local/x", root=root, video_backend="pyav")
    assert (ds.meta.total_episodes, ds.meta.total_frames) == (2, sum(r.steps for r in res.episodes))
    assert ds[0]["task"] == res.episodes[0].prompt
    merged = merge_with_standin(root, tmp_path, standin_episodes=2, frames=4)
    assert merged.meta.total_episodes == 4 and merged.meta.total_frames == ds.meta.total_frames + 8


def test_a_suite_without_a_recording_layout_refuses_record_up_front(tmp_path, monkeypatch):
    import dataclasses

    from molmo_lerobot.errors import RunError
    from molmo_lerobot.runner.evaluate import run_evaluation
    from molmo_lerobot.suites import plugin

    monkeypatch.setattr(plugin, "PUSHT", dataclasses.replace(plugin.PUSHT, recording=None))
    with pytest.raises(RunError, match=r"record=true: env suite 'pusht' \(benchmark=pusht\) has no recording layout"):
        run_evaluation(compose(["policy=random", "benchmark=pusht", "record=true", "limit=1", "progress=false",
                                f"output_dir={tmp_path}"]))
    assert not tmp_path.joinpath("episodes.jsonl").exists()
