"""LeRobot recording with synthetic rollouts: shards per worker, merge, eval records, torn shards."""

from __future__ import annotations

import json
import shutil

import export_synthetic as S  # tests/export is on sys.path (pytest's prepend import mode)
import numpy as np
import pytest

from molmo_lerobot.export.frames import FrameLayout
from molmo_lerobot.export.merge import EVAL_EPISODES, read_eval_records
from molmo_lerobot.export.recorder import LeRobotRecorderFactory, RecordConfigError
from molmo_lerobot.export.shards import SHARDS_DIR, list_shards
from molmo_lerobot.features import FeatureError
from molmo_lerobot.run_config import RunConfig

CFG = {"benchmark": {"name": "synth_v1"}, "policy": {"name": "scripted"},
       "timing": {"policy_dt_ms": 66.0}, "hub": {"repo_id": None, "private": False}, "push": False}


def _load(root, repo_id):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(repo_id, root=root, video_backend="pyav")


@pytest.fixture(scope="module")
def two_worker_run(tmp_path_factory):
    """Two workers; one errored episode, one episode retried after a worker died, one torn shard."""
    import multiprocessing as mp

    out = tmp_path_factory.mktemp("run")
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    w0 = factory.make("w0g0", out)
    results = {
        0: S.run_episode(w0, 0, 10, success_from=5),
        2: S.run_episode(w0, 2, 8, success_from=3, error="RuntimeError: boom"),
    }
    # worker w1g0 saves episode 1, then is SIGKILLed inside episode 3: that shard is torn and skipped
    child = mp.get_context("fork").Process(target=S.record_then_die,
                                           args=(factory, out, "w1g0", [(1, 12, None)], (3, 7)))
    child.start()
    child.join(120)
    assert child.exitcode == -9
    results[1] = S.run_episode(S.NullRecorder(), 1, 12, success_from=None)
    w1b = factory.make("w1g1", out)  # the replacement worker reruns episode 3 (the one in flight)
    results[3] = S.run_episode(w1b, 3, 7, success_from=1)
    results[4] = S.run_episode(w0, 4, 9, success_from=8)
    results[5] = S.run_episode(S.NullRecorder(), 5, 6, success_from=None)  # its recording was lost
    w0.close()
    w1b.close()
    ordered = [results[i] for i in sorted(results)]
    summary = S.summary_for(ordered)
    shards = list_shards(out)
    factory.finalize(out, ordered, summary)
    return out, factory, ordered, summary, shards


def test_shards_are_per_worker_and_a_torn_one_is_marked(two_worker_run):
    _, factory, _, _, shards = two_worker_run
    names = {s.root.name.split(f"{factory.session}-")[1]: s.complete for s in shards}
    # a shard ends where a worker's episodes stop being consecutive (w0: 0, then 2 and 4); the
    # errored episode 2 is discarded without a shard of its own
    assert names == {"w0g0-s000": True, "w0g0-s001": True, "w1g0-s000": True, "w1g0-s001": False,
                     "w1g1-s000": True}


def test_dataset_episodes_follow_benchmark_order_and_carry_their_provenance(two_worker_run):
    """Workers finished 0, 4 (w0) before 1 (w1g0) and 3 (w1g1): the dataset still reads 0, 1, 3, 4."""
    import pyarrow.dataset as pads

    out, _factory, _, _, _ = two_worker_run
    records = [r for r in read_eval_records(out / "dataset") if r["episode_index"] is not None]
    assert [(r["episode_index"], r["benchmark_episode_index"]) for r in records] == [(0, 0), (1, 1), (2, 3), (3, 4)]
    frames = pads.dataset(str(out / "dataset" / "data"), format="parquet").to_table().to_pandas()
    per_episode = frames.groupby("episode_index")[["eval.episode_index", "eval.seed"]].agg(set)
    assert per_episode["eval.episode_index"].tolist() == [{0}, {1}, {3}, {4}]
    assert per_episode["eval.seed"].tolist() == [{1000}, {1001}, {1003}, {1004}]
    info = json.loads((out / "dataset" / "meta" / "info.json").read_text())
    assert info["robot_type"] == "synth_arm"


def test_merged_dataset_loads_and_matches_eval_records(two_worker_run):
    out, factory, results, _, _ = two_worker_run
    ds = _load(out / "dataset", factory.repo_id)
    records = read_eval_records(out / "dataset")
    stored = [r for r in records if r["episode_index"] is not None]
    # ep 2 errored (never saved); the torn copy of ep 3 is skipped, its rerun stored
    assert {r["benchmark_episode_index"] for r in stored} == {0, 1, 3, 4}
    assert [r["benchmark_episode_index"] for r in records] == [0, 1, 2, 3, 4, 5]
    assert ds.num_episodes == 4 and ds.fps == 15
    by_bench = {r.episode_index: r for r in results}
    for rec in stored:
        ep = ds.meta.episodes[rec["episode_index"]]
        assert ep["length"] == by_bench[rec["benchmark_episode_index"]].steps
        last = ds[ep["dataset_to_index"] - 1]
        assert bool(last["next.success"]) == rec["success"] == by_bench[rec["benchmark_episode_index"]].success
        assert bool(last["next.done"])
        first = ds[ep["dataset_from_index"]]
        # the video frame is the right episode's first image (brightness encodes the episode)
        level = (rec["benchmark_episode_index"] * 37) % 250 / 255.0
        assert float(first["observation.images.exo"].mean()) == pytest.approx(level, abs=0.03)
        assert first["task"] == "pick up the mug"
    why = {r["benchmark_episode_index"]: r["not_recorded"] for r in records}
    assert why[2] == "episode error" and "killed or crashed" in why[5] and why[1] is None
    assert {"seed", "house_index", "success_once", "policy", "benchmark", "benchmark_sha256"} <= set(records[0])


def test_feature_names_are_joint_names(two_worker_run):
    out, factory, _, _, _ = two_worker_run
    feats = _load(out / "dataset", factory.repo_id).meta.features
    assert feats["observation.state"]["names"] == ["j1", "j2", "j3", "finger_left", "finger_right"]
    assert feats["action"]["names"] == ["j1", "j2", "j3", "gripper"]
    assert feats["observation.images.wrist"]["dtype"] == "video"
    assert "next.reward" not in feats  # the synthetic task defines no reward


def test_results_card_and_cleanup(two_worker_run):
    out, _, _, summary, _ = two_worker_run
    root = out / "dataset"
    assert json.loads((root / "results.json").read_text())["n_episodes"] == summary.n_episodes == 6
    card = (root / "README.md").read_text()
    assert "| **all** | 6 | 50.0% |" in card and "meta/eval/episodes.jsonl" in card
    info = json.loads((root / "meta/eval/info.json").read_text())
    assert info["n_recorded"] == 4 and len(info["torn_shards"]) == 1
    assert info["fps_exact"] == pytest.approx(15.1515, 1e-3)
    assert not (out / SHARDS_DIR).exists()
    assert not list(out.glob(".dataset-merge-*"))
    assert (root / EVAL_EPISODES).is_file()


def test_the_card_says_in_prose_what_the_data_is_and_its_limitations(two_worker_run):
    import re

    card = (two_worker_run[0] / "dataset" / "README.md").read_text()
    for said in ("synthetic", "simulated", "MuJoCo", "Robot: `synth_arm`", "5 joint positions",
                 "2 simulated RGB camera(s), `exo` (32x24), `wrist` (32x24), at 15 fps", "`pick` (6 episodes)",
                 "e.g. \"pick up the mug\"", "**Scores.**", "**Limitations.**", "real robot"):
        assert said in card, said
    # lerobot-quality-gates' card checks: these terms, and mock/synthetic/tutorial status
    assert all(re.search(term, card, re.I) for term in ("robot", "sensor", "task", "limitation", "synthetic"))
    assert "scripted expert that end" not in card  # no episode was cut at its success hold


def test_a_local_datasets_card_links_no_hub_viewer_but_says_how_to_view_it(two_worker_run):
    """push=false: the Hub's viewer would open nothing (no such dataset there); LeRobot's local viewer can."""
    card = (two_worker_run[0] / "dataset" / "README.md").read_text()
    assert "huggingface.co/spaces/lerobot/visualize_dataset" not in card
    assert f"`lerobot-dataset-viz --repo-id {two_worker_run[1].repo_id} --root . --episode-index 0`" in card


def test_resume_adds_new_shards_to_the_previous_dataset(two_worker_run, tmp_path):
    out0, _, results, _, _ = two_worker_run
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))  # a new invocation: new session
    w = factory.make("w0g0", out)  # same worker id as the first run: must not collide
    new = S.run_episode(w, 6, 6, success_from=0, reward=False)
    w.close()
    everything = [*results, new]
    factory.finalize(out, everything, S.summary_for(everything))
    records = read_eval_records(out / "dataset")
    stored = {r["benchmark_episode_index"]: r["episode_index"] for r in records if r["episode_index"] is not None}
    assert list(stored) == [0, 1, 3, 4, 6] and list(stored.values()) == [0, 1, 2, 3, 4]
    assert _load(out / "dataset", factory.repo_id).num_episodes == 5


def test_reward_feature_when_the_task_defines_one(tmp_path):
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    w = factory.make("w0g0", tmp_path)
    r = S.run_episode(w, 0, 5, success_from=2, reward=True)
    w.close()
    factory.finalize(tmp_path, [r], S.summary_for([r]))
    ds = _load(tmp_path / "dataset", factory.repo_id)
    assert [float(ds[i]["next.reward"]) for i in range(5)] == [0, 0, 1, 1, 1]


def test_all_errors_write_no_dataset(tmp_path):
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    w = factory.make("w0g0", tmp_path)
    r = S.run_episode(w, 0, 6, success_from=None, error="ValueError: bad action")
    w.close()
    factory.finalize(tmp_path, [r], S.summary_for([r]))
    assert not (tmp_path / "dataset").exists()


def test_frame_layout_rejects_mismatched_steps():
    info = S.info(0, 5)
    layout = FrameLayout.from_step(info, S.obs(0, 0), None)
    bad = S.obs(0, 1)
    bad["images"]["wrist"] = np.zeros((S.H + 1, S.W, 3), np.uint8)
    with pytest.raises(FeatureError, match=r"observation.images.wrist"):
        layout.frame(bad, {"arm": np.zeros(3), "gripper": np.zeros(1)}, None, False, False, "t", S.info(0, 5))
    with pytest.raises(FeatureError, match="action: move group 'arm' has 2 values"):
        layout.frame(S.obs(0, 1), {"arm": np.zeros(2), "gripper": np.zeros(1)}, None, False, False, "t", S.info(0, 5))
    no_cam = S.obs(0, 0)
    del no_cam["images"]["exo"]
    with pytest.raises(FeatureError, match="camera 'exo'"):
        FrameLayout.from_step(info, no_cam, None)


@pytest.mark.parametrize(("hub", "push", "match"), [
    ({"repo_id": None}, True, "needs hub.repo_id"),
    ({"repo_id": "no-namespace"}, True, "must be <namespace>/<name>"),
    ({"repo_id": "bad//id"}, True, "not a valid dataset id"),
    ({"repo_id": "a/b/c"}, False, "not a valid dataset id"),
])
def test_hub_settings_are_validated(hub, push, match):
    with pytest.raises(RecordConfigError, match=match):
        LeRobotRecorderFactory.from_config(RunConfig.of({**CFG, "hub": hub, "push": push}))


def test_default_repo_id_and_pickling():
    import pickle

    f = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    assert f.repo_id == "local/synth_v1-scripted" and f.fps == 15
    assert pickle.loads(pickle.dumps(f)) == f



def test_a_failed_save_leaves_the_shard_torn_and_never_merged(tmp_path, monkeypatch):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    factory.shard_episodes = 1  # episode 0's shard is finished before episode 1's save fails
    w = factory.make("w0g0", tmp_path)
    first = S.run_episode(w, 0, 5, success_from=1)

    def disk_full(self, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(LeRobotDataset, "save_episode", disk_full)
    with pytest.raises(OSError, match="No space"):
        S.run_episode(w, 1, 5, success_from=1)
    monkeypatch.undo()
    w.close()
    assert [s.complete for s in list_shards(tmp_path)] == [True, False]
    second = S.run_episode(S.NullRecorder(), 1, 5, success_from=1)
    second.output_errors = ["LeRobotRecorder: OSError: [Errno 28] No space left on device"]  # as the worker saw it
    factory.finalize(tmp_path, [first, second], S.summary_for([first, second]))
    records = read_eval_records(tmp_path / "dataset")  # the torn shard's episode is never merged
    assert [r["episode_index"] for r in records] == [0, None]
    assert records[1]["not_recorded"] == "output failed: LeRobotRecorder: OSError: [Errno 28] No space left on device"
    assert factory.missing(tmp_path, [first, second]) == {1}, "a resume records it"


def test_shards_rotate_and_merge_in_order(tmp_path):
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    factory.shard_episodes = 2
    w = factory.make("w0g0", tmp_path)
    results = [S.run_episode(w, i, 4 + i, success_from=i) for i in range(5)]
    w.close()
    assert len(list_shards(tmp_path)) == 3
    factory.finalize(tmp_path, results, S.summary_for(results))
    ds = _load(tmp_path / "dataset", factory.repo_id)
    assert [int(ds.meta.episodes[i]["length"]) for i in range(5)] == [4, 5, 6, 7, 8]


def test_an_episode_stored_twice_is_merged_once(tmp_path):
    """A finished shard holds episode 3, whose result never reached the supervisor; the rerun stores it again."""
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    a = factory.make("w0g0", tmp_path)
    r2 = S.run_episode(a, 2, 6, success_from=2)
    S.run_episode(a, 3, 5, success_from=None)  # first attempt: failure recorded in shard A
    a.close()
    b = factory.make("w0g1", tmp_path)
    r3 = S.run_episode(b, 3, 5, success_from=4)  # the attempt whose result counts (success)
    b.close()
    factory.finalize(tmp_path, [r2, r3], S.summary_for([r2, r3]))
    ds = _load(tmp_path / "dataset", factory.repo_id)
    stored = {r["benchmark_episode_index"]: r["episode_index"] for r in read_eval_records(tmp_path / "dataset")}
    assert ds.num_episodes == 2 and sorted(stored) == [2, 3]
    last = ds[int(ds.meta.episodes[stored[3]]["dataset_to_index"]) - 1]
    assert bool(last["next.success"]) is True  # the copy that matches the result was kept


def _resume_storing_episode_2(two_worker_run, tmp_path):
    """A copy of the two-worker run resumed with episode 2 (errored before) now stored: its dataset is cut
    around the new episode. Returns the run directory and its recorder factory."""
    out0, _, results, _, _ = two_worker_run
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    w = factory.make("w0g0", out)
    redo = S.run_episode(w, 2, 5, success_from=1)
    w.close()
    everything = [redo if r.episode_index == 2 else r for r in results]
    factory.finalize(out, everything, S.summary_for(everything))
    return out, factory


def test_a_new_episode_between_previous_ones_keeps_benchmark_order(two_worker_run, tmp_path):
    """Resume stores episode 2 (errored before): the previous dataset is cut around it, frames intact."""
    out, factory = _resume_storing_episode_2(two_worker_run, tmp_path)
    records = [r for r in read_eval_records(out / "dataset") if r["episode_index"] is not None]
    assert [r["benchmark_episode_index"] for r in records] == [0, 1, 2, 3, 4]
    ds = _load(out / "dataset", factory.repo_id)
    for rec in records:
        ep = ds.meta.episodes[rec["episode_index"]]
        first = ds[ep["dataset_from_index"]]
        assert int(first["eval.episode_index"]) == rec["benchmark_episode_index"]
        level = (rec["benchmark_episode_index"] * 37) % 250 / 255.0
        assert float(first["observation.images.exo"].mean()) == pytest.approx(level, abs=0.03)


def test_portable_paths_name_no_place_of_this_machine(tmp_path):
    from molmo_lerobot.export.portable import portable

    run = tmp_path / "run"
    record = {"output_dir": str(run), "video": str(run / "dataset" / "videos"), "n": 3, "url": "http://host/a/b",
              "repo": "me/pick", "rel": "runs/x",
              "error": f"FileNotFoundError: {tmp_path}/objects/mug.xml is missing. See /root/.cache/x.",
              "paths": [str(tmp_path / "bench" / "pick_v1"), "/"], str(tmp_path / "key"): 1}
    assert portable(record, run) == {
        "output_dir": ".", "video": "dataset/videos", "n": 3, "url": "http://host/a/b", "repo": "me/pick",
        "rel": "runs/x", "error": "FileNotFoundError: <local>/mug.xml is missing. See <local>/x.",
        "paths": ["<local>/pick_v1", "<local>"], "<local>/key": 1}


def test_a_merge_killed_between_the_swap_renames_is_completed_by_the_next(two_worker_run, tmp_path, monkeypatch):
    """A resume's merge is killed after ``dataset`` moved away and before the new one moved in:
    the next merge finds the intact copy and puts it in place (nothing recorded is lost), leaves
    no ``.dataset-merge-*`` behind, and a resume knows which episodes the dataset still lacks."""
    from molmo_lerobot import fileio

    out0, _, results, _, _ = two_worker_run
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    w = factory.make("w0g0", out)
    redo = S.run_episode(w, 2, 5, success_from=1)  # the resume stores episode 2 (errored before)
    w.close()
    everything = [redo if r.episode_index == 2 else r for r in results]
    replace = fileio.replace

    def killed_mid_swap(src, dst, **kwargs):
        if src.name == "dataset" and src.parent.name.startswith(".dataset-merge-"):
            raise KeyboardInterrupt  # stands for the SIGKILL: the previous dataset is already moved away
        return replace(src, dst, **kwargs)

    monkeypatch.setattr(fileio, "replace", killed_mid_swap)
    with pytest.raises(KeyboardInterrupt):
        factory.finalize(out, everything, S.summary_for(everything))
    monkeypatch.undo()
    assert not (out / "dataset").exists() and list(out.glob(".dataset-merge-*"))

    again = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))  # the next resume: a new session
    again.finalize(out, everything, S.summary_for(everything))
    records = [r for r in read_eval_records(out / "dataset") if r["episode_index"] is not None]
    assert [r["benchmark_episode_index"] for r in records] == [0, 1, 2, 3, 4]
    assert _load(out / "dataset", again.repo_id).num_episodes == 5
    assert not list(out.glob(".dataset-merge-*")) and not (out / SHARDS_DIR).exists()
    assert again.missing(out, everything) == {5}, "episode 5 finished but its recording was lost"


def _lerobot_stats(root, repo_id) -> dict:
    """The stats LeRobot computes on a dataset's data: per episode (compute_episode_stats), aggregated."""
    from lerobot.datasets.compute_stats import aggregate_stats, compute_episode_stats

    ds = _load(root, repo_id)
    numeric = {k: v for k, v in ds.meta.features.items() if v["dtype"] not in ("image", "video", "string")}
    table = ds.hf_dataset.with_format("numpy")
    per_episode = []
    for ep in range(ds.num_episodes):
        meta = ds.meta.episodes[ep]
        rows = table[int(meta["dataset_from_index"]):int(meta["dataset_to_index"])]
        per_episode.append(compute_episode_stats({k: np.asarray(rows[k]) for k in numeric}, numeric))
    return aggregate_stats(per_episode)


def _assert_stats_match(root, repo_id) -> dict:
    expected, stored = _lerobot_stats(root, repo_id), _load(root, repo_id).meta.stats
    for column, stats in expected.items():
        for stat, value in stats.items():
            np.testing.assert_allclose(np.asarray(stored[column][stat], dtype=np.float64),
                                       np.asarray(value, dtype=np.float64), rtol=1e-6, atol=1e-9,
                                       err_msg=f"{column}.{stat}")
    return stored


def test_merged_stats_are_lerobots_stats_of_the_merged_data(tmp_path):
    """3 episodes (245 frames, 3 tasks) from two workers' shards: the bookkeeping columns are re-indexed."""
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    w0, w1 = factory.make("w0g0", tmp_path), factory.make("w1g0", tmp_path)
    results = [S.run_episode(w0, 0, 80, success_from=70, prompt="pick up the mug"),
               S.run_episode(w1, 1, 85, success_from=None, prompt="pick up the bowl"),
               S.run_episode(w1, 2, 80, success_from=60, prompt="pick up the plate")]
    w0.close()
    w1.close()
    factory.finalize(tmp_path, results, S.summary_for(results))
    stats = _assert_stats_match(tmp_path / "dataset", factory.repo_id)
    for column, high in (("episode_index", 2), ("task_index", 2), ("index", 244), ("frame_index", 84)):
        assert (float(stats[column]["min"][0]), float(stats[column]["max"][0])) == (0, high), column
    assert int(stats["index"]["count"][0]) == 245


def test_stats_after_a_resume_cut_the_previous_dataset(two_worker_run, tmp_path):
    """Resume stores episode 2 between previous ones: the previous dataset is cut (delete_episodes)."""
    out, factory = _resume_storing_episode_2(two_worker_run, tmp_path)
    stats = _assert_stats_match(out / "dataset", factory.repo_id)
    assert float(stats["episode_index"]["max"][0]) == 4
