"""``molmo-eval benchmark=aloha_insertion`` / ``aloha_transfer_cube``: gym-aloha's episodes through our workers, its
recording in the layout of LeRobot's ALOHA sim datasets, and its env process lost as LIBERO's is.

gym-aloha runs in the ALOHA venv (``make .aloha-venv``); these tests skip without it. A step with its frame drawn
costs ~0.1 s here, so the runs play short episodes.
"""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest
import standin_dataset

from molmo_lerobot.benchmark_kinds import BenchmarkKindError, run_kind
from molmo_lerobot.config import compose
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.suites import aloha
from molmo_lerobot.suites.benchmark import SuiteBenchmark, plan_problems, suite_plan
from molmo_lerobot.suites.pipe import SuiteProcessError
from molmo_lerobot.suites.plugin import ALOHA

#: ``lerobot/aloha_sim_insertion_human``'s features (its ``meta/info.json``), fps 50, robot ``aloha``. Written out
#: here, not imported from the code under test, so that a drift of ours fails.
MOTORS = {"motors": ["left_waist", "left_shoulder", "left_elbow", "left_forearm_roll", "left_wrist_angle",
                     "left_wrist_rotate", "left_gripper", "right_waist", "right_shoulder", "right_elbow",
                     "right_forearm_roll", "right_wrist_angle", "right_wrist_rotate", "right_gripper"]}
THEIR_FEATURES = {
    "observation.images.top": {"dtype": "video", "shape": (480, 640, 3), "names": ["height", "width", "channel"]},
    "observation.state": {"dtype": "float32", "shape": (14,), "names": MOTORS},
    "action": {"dtype": "float32", "shape": (14,), "names": MOTORS},
    "next.done": {"dtype": "bool", "shape": (1,), "names": None},
}
THEIR_FPS, THEIR_ROBOT = 50, "aloha"
THEIR_TASK = "Insert the peg into the socket."

needs_venv = pytest.mark.skipif(not (aloha.aloha_venv() / "bin" / "python").exists(),
                                reason=f"no ALOHA venv at {aloha.aloha_venv()} (build it: make .aloha-venv)")


def write_standin(root):
    """One three-frame episode in ``lerobot/aloha_sim_insertion_human``'s layout, by LeRobot's own writer."""

    def frame(rng, i):
        return {"observation.images.top": rng.integers(0, 255, (480, 640, 3), dtype=np.uint8),
                "observation.state": rng.uniform(-1, 1, 14).astype(np.float32),
                "action": rng.uniform(-1, 1, 14).astype(np.float32), "next.done": np.array([i == 2]),
                "task": THEIR_TASK}

    return standin_dataset.write_standin(root, "standin/aloha", THEIR_FEATURES, THEIR_FPS, THEIR_ROBOT, 1, 3, frame,
                                         seed=3)


def assert_aloha_layout(root) -> None:
    """``meta/info.json`` of a recording: exactly ``lerobot/aloha_sim_insertion_human``'s features, fps and robot."""
    info = json.loads((root / "meta/info.json").read_text())
    own = {k: {f: v[f] for f in ("dtype", "shape", "names")} for k, v in info["features"].items()
           if k not in ("timestamp", "frame_index", "episode_index", "index", "task_index")}
    assert own == {k: {**v, "shape": list(v["shape"])} for k, v in THEIR_FEATURES.items()}
    assert (info["fps"], info["robot_type"]) == (THEIR_FPS, THEIR_ROBOT)


def merge_with_standin(ours, tmp_path):
    """LeRobot's aggregate of ``ours`` and a one-episode, three-frame stand-in; the merged ``LeRobotDataset``."""
    from lerobot.datasets.aggregate import aggregate_datasets
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    aggregate_datasets(["ours/aloha", "standin/aloha"], "merged/aloha", roots=[ours, write_standin(tmp_path / "s")],
                       aggr_root=tmp_path / "merged")
    return LeRobotDataset("merged/aloha", root=tmp_path / "merged", video_backend="pyav")


@needs_venv
def test_a_two_worker_aloha_run_scores_per_task(tmp_path):
    """``molmo-eval policy=random benchmark=aloha_insertion workers=2 limit=2``: the per-task table, lerobot-eval's
    seeding (episode k: seed k) and its prompt (gym-aloha's ``task``)."""
    out = tmp_path / "run"
    run_evaluation(compose(["policy=random", "benchmark=aloha_insertion", "workers=2", "limit=2", "horizon=6",
                            "progress=false", f"output_dir={out}"]))
    doc = json.loads((out / "results.json").read_text())
    assert doc["n_episodes"] == 2 and doc["n_errors"] == 0
    assert list(doc["per_task"]) == ["aloha_insertion/AlohaInsertion-v0"]
    assert doc["per_task"]["aloha_insertion/AlohaInsertion-v0"]["instructions"] == ["insertion"]
    lines = sorted(map(json.loads, (out / "episodes.jsonl").read_text().splitlines()), key=lambda e: e["episode_index"])
    assert [(e["seed"], e["steps"], e["prompt"], e["error"]) for e in lines] == [(0, 6, "insertion", None),
                                                                                   (1, 6, "insertion", None)]


@needs_venv
def test_an_aloha_recording_has_lerobots_layout_and_merges_with_theirs(tmp_path):
    """Two episodes of gym-aloha's env through the rollout loop, a ``SuiteSession`` and the run's recorder (what a
    ``record=true`` worker does, without starting one)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from molmo_lerobot.export.recorder import LeRobotRecorderFactory
    from molmo_lerobot.policies.random_policy import RandomPolicy
    from molmo_lerobot.results import summarize
    from molmo_lerobot.runner.rollout import rollout

    out = tmp_path / "run"
    config = compose(["policy=random", "benchmark=aloha_insertion", "record=true", "horizon=4", f"output_dir={out}"])
    run = RunConfig.of(config)
    kind = run_kind(Plugins(), run)
    factory = LeRobotRecorderFactory.from_config(run, kind.recording_layout(run))
    recorder, sessions = factory.make("w0", out), kind.sessions_of(run)
    bench = kind.benchmark_of(run)
    results, seen = [], []
    try:
        for i, episode in enumerate(bench.episodes[:2]):
            policy = RandomPolicy({})
            session = sessions.open(suite_plan(i, bench.suite, episode, True), policy, end_on_success=True)
            seen.append(session.observe()["qpos"][aloha.MOVE_GROUP].copy())
            recorder.start_episode(session.recorder_info(expert=False, extra={}))
            results.append(rollout(session, policy, [recorder], "random"))
            recorder.end_episode(results[-1])
    finally:
        sessions.close()
    recorder.close()
    summary = summarize(results, benchmark={"name": "aloha_insertion", "sha256": "ab" * 32, "n_episodes": 2},
                        policy={"name": "random"}, seed=0)
    factory.finalize(out, results, summary)
    root = out / "dataset"
    assert_aloha_layout(root)
    ds = LeRobotDataset(factory.repo_id, root=root, video_backend="pyav")
    assert (ds.meta.total_episodes, ds.meta.total_frames) == (2, 8)
    frames = ds.hf_dataset.with_format("numpy")  # the columns, without decoding the video
    assert [bool(d) for d in frames["next.done"]] == [False, False, False, True] * 2
    assert np.array_equal(frames["observation.state"][0], seen[0])
    assert np.array_equal(frames["observation.state"][4], seen[1])
    assert tuple(ds[0]["observation.images.top"].shape) == (3, 480, 640)
    assert "Robot: `aloha`" in (root / "README.md").read_text()
    merged = merge_with_standin(root, tmp_path)
    assert (merged.meta.total_episodes, merged.meta.total_frames) == (3, 11)
    assert THEIR_TASK in merged.meta.tasks.index
    assert np.array_equal(merged.hf_dataset.with_format("numpy")["action"][:8], frames["action"])


@pytest.mark.slow
@needs_venv
def test_a_recorded_two_worker_aloha_run_merges_with_lerobots_layout(tmp_path):
    """``molmo-eval policy=random benchmark=aloha_insertion workers=2 limit=2 record=true`` (25–50 s here, most of it
    the recording workers' start)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    out = tmp_path / "run"
    run_evaluation(compose(["policy=random", "benchmark=aloha_insertion", "workers=2", "limit=2", "horizon=6",
                            "record=true", "progress=false", f"output_dir={out}"]))
    assert json.loads((out / "results.json").read_text())["n_errors"] == 0
    root = out / "dataset"
    assert_aloha_layout(root)
    ds = LeRobotDataset("local/x", root=root, video_backend="pyav")
    assert (ds.meta.total_episodes, ds.meta.total_frames) == (2, 12)
    assert [bool(d) for d in ds.hf_dataset.with_format("numpy")["next.done"]] == ([False] * 5 + [True]) * 2
    merged = merge_with_standin(root, tmp_path)
    assert (merged.meta.total_episodes, merged.meta.total_frames) == (3, 15)


@needs_venv
def test_a_lost_aloha_process_fails_the_episode_as_infrastructure_and_is_replaced():
    """Its process killed mid-episode: the step is the machinery's failure, and the worker's next episode starts a
    new process (what LIBERO's gets)."""
    config = RunConfig.of(compose(["policy=random", "benchmark=aloha_transfer_cube", "horizon=3"]))
    kind = run_kind(Plugins(), config)
    bench = kind.benchmark_of(config)
    assert [(e.task, e.instruction) for e in bench.episodes[:1]] == [("AlohaTransferCube-v0", "transfer_cube")]
    sessions = kind.sessions_of(config)
    try:
        session = sessions.open(suite_plan(0, bench.suite, bench.episodes[0], True), None, end_on_success=True)
        state = session.observe(images=False)["qpos"][aloha.MOVE_GROUP]
        os.kill(session.suite.pid, signal.SIGKILL)
        with pytest.raises(SuiteProcessError, match="aloha_server"):
            session.step({aloha.MOVE_GROUP: np.asarray(state)})
        again = sessions.open(suite_plan(0, bench.suite, bench.episodes[0], True), None, end_on_success=True)
        assert again.suite is not session.suite and again.suite.alive
        assert np.array_equal(again.observe()["qpos"][aloha.MOVE_GROUP], state)
        assert again.observe()["images"][aloha.CAMERA].shape == (480, 640, 3)
    finally:
        sessions.close()


def test_a_missing_aloha_venv_names_the_make_target(tmp_path):
    with pytest.raises(SuiteProcessError, match=r"make \.aloha-venv"):
        aloha.AlohaSuite(tmp_path / "nowhere")


def test_aloha_options_and_plan_problems():
    config = RunConfig.of(compose(["policy=random", "benchmark=aloha_insertion"]))
    kind = run_kind(Plugins(), config)
    assert kind.options_of(config).model_dump(exclude={"name", "path"}) == {"episodes_per_task": 50}
    sized = RunConfig.of(compose(["policy=random", "benchmark=aloha_insertion", "+benchmark.image_size=96"]))
    with pytest.raises(BenchmarkKindError, match=r"benchmark.image_size: not an option .*: episodes_per_task\)"):
        kind.options_of(sized)
    tasks = [{"task_id": 0, "task": "AlohaInsertion-v0", "instruction": "insertion"}]
    episodes = aloha.plan_episodes("aloha_insertion", tasks, 2, seed=4)
    assert [(e.seed, e.horizon) for e in episodes] == [(4, 400), (5, 400)]
    bad = [*episodes, aloha.AlohaEpisode("aloha_insertion", "AlohaTransferCube-v0", 9, 400, "insertion")]
    bench = SuiteBenchmark("aloha_insertion", bad, None, ALOHA)  # type: ignore[arg-type]
    assert plan_problems(bench, tasks) == [
        "aloha_insertion episode 2: task 'AlohaTransferCube-v0': aloha_insertion's tasks are 'AlohaInsertion-v0'"]


@needs_venv
def test_molmo_bench_list_reads_gym_aloha_from_the_aloha_venv(capsys):
    """``molmo-bench list`` names ALOHA's source as the ALOHA venv has it (it said "not installed": gym-aloha is not
    in ``.venv``)."""
    from molmo_lerobot.cli.bench import main

    assert main(["list"]) == 0
    [line] = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("env suite aloha:")]
    assert line.startswith("env suite aloha: gym-aloha 0.1.") and "not installed" not in line, line
