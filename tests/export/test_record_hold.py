"""``record_hold_steps``: an expert's recording ends a few steps after its first success; the
rollout, and so every score, runs on to the horizon."""

from __future__ import annotations

import json

import export_synthetic as S  # tests/export is on sys.path (pytest's prepend import mode)
import numpy as np
import pytest

from molmo_lerobot.config import compose
from molmo_lerobot.export.merge import read_eval_records
from molmo_lerobot.export.recorder import LeRobotRecorderFactory
from molmo_lerobot.run_config import RunConfig, RunConfigError
from molmo_lerobot.runner.evaluate import run_evaluation

CFG = {"benchmark": {"name": "synth_v1"}, "policy": {"name": "scripted"},
       "timing": {"policy_dt_ms": 66.0}, "hub": {"repo_id": None, "private": False}, "push": False,
       "record_min_frames": 0}  # the synthetic episodes are shorter than the default minimum


def _episodes(root, repo_id):
    """Per dataset episode: (frames, next.done flags, arm state's step column)."""
    import pandas as pd

    frames = pd.concat(pd.read_parquet(p) for p in sorted((root / "data").rglob("*.parquet")))
    return {int(e): (len(g), list(g["next.done"]), [int(s[1]) for s in g["observation.state"]])
            for e, g in frames.groupby("episode_index")}


def test_an_experts_recording_ends_its_hold_after_the_first_success(tmp_path):
    factory = LeRobotRecorderFactory.from_config(RunConfig.of({**CFG, "record_hold_steps": 2}))
    w = factory.make("w0g0", tmp_path)
    results = [
        S.run_episode(w, 0, 12, success_from=3, expert=True),  # success at 3: steps 0..5 recorded
        S.run_episode(w, 1, 10, success_from=3, success_until=5, expert=True),  # lost after the hold began
        S.run_episode(w, 2, 8, success_from=2),  # not an expert: recorded in full
        S.run_episode(w, 3, 9, success_from=None, expert=True),  # never succeeds: recorded in full
        S.run_episode(w, 4, 9, success_from=7, expert=True),  # the horizon comes first
    ]
    w.start_episode(S.info(5, 12, expert=True))  # images are rendered only while recording
    for t in range(5):
        w.record_step(S.obs(5, t), {"arm": np.zeros(3), "gripper": np.zeros(1)}, None, t >= 2, False)
    assert [w.wants_images_at(t, 12) for t in (4, 5)] == [True, False]
    results.append(S.run_episode(S.NullRecorder(), 5, 12, success_from=2))
    w.end_episode(results[-1])
    w.close()
    factory.finalize(tmp_path, results, S.summary_for(results))  # its checks pass on the held episodes

    root = tmp_path / "dataset"
    stored = _episodes(root, factory.repo_id)
    assert {e: n for e, (n, _, _) in stored.items()} == {0: 6, 1: 6, 2: 8, 3: 9, 4: 9, 5: 5}
    for n, done, steps in stored.values():
        assert steps == list(range(n)) and done == [False] * (n - 1) + [True]  # the first n steps, then done
    assert "3 stored episode(s) are demonstrations of a scripted expert" in (root / "README.md").read_text()
    records = {r["benchmark_episode_index"]: r for r in read_eval_records(root)}
    assert [(records[i]["steps"], records[i]["frames"], records[i]["success"]) for i in range(6)] == [
        (12, 6, True), (10, 6, False), (8, 8, True), (9, 9, False), (9, 9, True), (12, 5, True)]
    # a resumed run keeps the held episodes as they are and adds the new one
    w = factory.make("w0g1", tmp_path)
    results.append(S.run_episode(w, 6, 7, success_from=0, expert=True))
    w.close()
    factory.finalize(tmp_path, results, S.summary_for(results))
    assert {e: n for e, (n, _, _) in _episodes(root, factory.repo_id).items()} == {
        0: 6, 1: 6, 2: 8, 3: 9, 4: 9, 5: 5, 6: 3}


def test_hold_null_records_the_whole_rollout(tmp_path):
    factory = LeRobotRecorderFactory.from_config(RunConfig.of({**CFG, "record_hold_steps": None}))
    w = factory.make("w0g0", tmp_path)
    results = [S.run_episode(w, 0, 12, success_from=3, expert=True)]
    w.close()
    factory.finalize(tmp_path, results, S.summary_for(results))
    assert _episodes(tmp_path / "dataset", factory.repo_id)[0][0] == 12


def test_an_experts_recording_keeps_record_min_frames(tmp_path):
    """The hold ends no recording before record_min_frames (lerobot-doctor's gate: no demonstration
    shorter than the policy's action chunk); the horizon still ends it."""
    factory = LeRobotRecorderFactory.from_config(RunConfig.of({**CFG, "record_hold_steps": 2, "record_min_frames": 9}))
    assert LeRobotRecorderFactory.from_config(RunConfig.of({k: v for k, v in CFG.items() if k != "record_min_frames"}
                                              )).min_frames == 100  # the default: ACT's and SmolVLA's chunk
    w = factory.make("w0g0", tmp_path)
    results = [S.run_episode(w, 0, 12, success_from=3, expert=True),  # held to 9 frames, not 6
               S.run_episode(w, 1, 7, success_from=3, expert=True),  # the horizon (7) comes first
               S.run_episode(w, 2, 12, success_from=8, expert=True)]  # the hold (8 + 2) is past the minimum
    w.close()
    factory.finalize(tmp_path, results, S.summary_for(results))
    assert {e: n for e, (n, _, _) in _episodes(tmp_path / "dataset", factory.repo_id).items()} == {0: 9, 1: 7, 2: 11}
    with pytest.raises(RunConfigError, match="record_min_frames: expected a non-negative integer, got -1"):
        LeRobotRecorderFactory.from_config(RunConfig.of({**CFG, "record_min_frames": -1}))


@pytest.mark.parametrize("hold", [-1, True, 2.5, "10"])
def test_record_hold_steps_is_validated(hold):
    with pytest.raises(RunConfigError, match="record_hold_steps: expected a non-negative integer or null"):
        LeRobotRecorderFactory.from_config(RunConfig.of({**CFG, "record_hold_steps": hold}))


def _frozen_fraction(actions: np.ndarray) -> float:
    """Share of frames whose action repeats the previous frame's (lerobot-doctor's "frozen actions")."""
    return float(np.mean(np.all(np.isclose(actions[1:], actions[:-1], rtol=0, atol=1e-6), axis=1)))


@pytest.mark.slow  # two 120-step pick_v1 rollouts, recorded (about 20 s)
def test_pick_v1_expert_recording_is_mostly_motion_and_scores_do_not_change(tmp_path):
    """The scripted expert succeeds around step 50 and holds still to the horizon: with the
    default hold its recording is mostly motion; the episode's outcome is the same as without."""
    import pandas as pd

    runs = {}
    for name, hold in (("held", []), ("full", ["record_hold_steps=null"])):
        out = tmp_path / name
        run_evaluation(compose(["policy=scripted", "benchmark=pick_v1", "workers=1", "limit=1", "horizon=120",
                                "record=true", "progress=false", f"output_dir={out}", *hold]))
        episodes = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
        data = pd.concat(pd.read_parquet(p) for p in sorted((out / "dataset" / "data").rglob("*.parquet")))
        runs[name] = episodes, data, json.loads((out / "results.json").read_text())
    (held, held_data, held_summary), (full, full_data, full_summary) = runs["held"], runs["full"]
    outcome = ("success", "success_once", "steps", "seed", "error", "house_index", "horizon")
    assert [{k: e[k] for k in outcome} for e in held] == [{k: e[k] for k in outcome} for e in full]
    assert held[0]["success"] and held[0]["steps"] == 120
    for key in ("success_rate", "success_once_rate", "n_success", "n_episodes"):
        assert held_summary[key] == full_summary[key]
    first = int(np.flatnonzero(full_data["next.success"].to_numpy())[0])
    kept = max(first + 11, 100)  # the default hold (10 steps), at least record_min_frames (100)
    assert len(held_data) == kept < len(full_data) == 120
    assert np.array_equal(np.stack(held_data["action"]), np.stack(full_data["action"])[:kept])
    frozen = _frozen_fraction(np.stack(held_data["action"]))
    print(f"repeated actions: {frozen:.1%} of {len(held_data)} frames held, "
          f"{_frozen_fraction(np.stack(full_data['action'])):.1%} of {len(full_data)} in full")
    assert frozen <= 0.30 < _frozen_fraction(np.stack(full_data["action"])), frozen
