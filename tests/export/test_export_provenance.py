"""What survives LeRobot's own ``lerobot-edit-dataset`` on our datasets, and what does not.

Kept by every edit: each frame's ``eval.episode_index`` / ``eval.seed`` (they are dataset
features) and ``robot_type``; so every edited episode still joins to its eval record.
Not kept: ``meta/eval/``, ``results.json`` and the card (LeRobot rebuilds ``meta/`` with its
own schema); they stay in the source dataset, or in LeRobot's ``<root>_old`` backup after an
in-place edit. The README's "After lerobot-edit-dataset" section says the same.
"""

from __future__ import annotations

import json
import sys

import export_synthetic as S  # tests/export is on sys.path (pytest's prepend import mode)
import pytest

from molmo_lerobot.export.merge import read_eval_records
from molmo_lerobot.export.recorder import LeRobotRecorderFactory
from molmo_lerobot.run_config import RunConfig

CFG = {"benchmark": {"name": "synth_v1"}, "policy": {"name": "scripted"},
       "timing": {"policy_dt_ms": 66.0}, "hub": {"repo_id": None, "private": False}, "push": False}
EVAL_FILES = ("meta/eval/episodes.jsonl", "meta/eval/info.json", "results.json", "README.md")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    a, b = factory.make("w0g0", out), factory.make("w1g0", out)
    results = [S.run_episode(a if i % 2 else b, i, 4 + i, success_from=2) for i in range(4)]
    a.close()
    b.close()
    factory.finalize(out, results, S.summary_for(results))
    return out / "dataset", factory.repo_id


def _edit(*args: str) -> None:
    """``lerobot-edit-dataset *args``: LeRobot's command, run in this process (its own argument parsing and
    handlers; a fresh interpreter would only re-import LeRobot)."""
    from lerobot.scripts.lerobot_edit_dataset import edit_dataset

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sys, "argv", ["lerobot-edit-dataset", *args])
        edit_dataset()


def _provenance(root) -> list[tuple[int, int]]:
    """(dataset episode, eval.episode_index) for every episode of the dataset at ``root``."""
    import pyarrow.dataset as pads

    frames = pads.dataset(str(root / "data"), format="parquet").to_table().to_pandas()
    per_ep = frames.groupby("episode_index")["eval.episode_index"].agg(set)
    assert all(len(v) == 1 for v in per_ep), "one benchmark episode per dataset episode"
    return [(int(ep), int(next(iter(v)))) for ep, v in per_ep.items()]


def _joins(edited, source) -> dict[int, dict]:
    """Each edited episode's eval record, found through its frames' eval.episode_index."""
    records = {r["benchmark_episode_index"]: r for r in read_eval_records(source)}
    return {ep: records[bench] for ep, bench in _provenance(edited)}


def test_delete_episodes_in_place_keeps_provenance_and_the_backup_keeps_the_records(recorded, tmp_path):
    import shutil

    source, repo_id = recorded
    root = tmp_path / "ds"
    shutil.copytree(source, root)
    _edit("--repo_id", repo_id, "--root", str(root), "--new_root", str(root),
          "--operation.type", "delete_episodes", "--operation.episode_indices", "[1]")
    backup = tmp_path / "ds_old"
    assert [b for _, b in _provenance(root)] == [0, 2, 3]
    joined = _joins(root, backup)  # the eval records stay in LeRobot's backup of the original
    assert [r["benchmark_episode_index"] for r in joined.values()] == [0, 2, 3]
    assert all(r["seed"] == 1000 + r["benchmark_episode_index"] for r in joined.values())
    info = json.loads((root / "meta/info.json").read_text())
    assert info["robot_type"] == "synth_arm" and "eval.episode_index" in info["features"]
    for name in EVAL_FILES:  # documented loss: LeRobot rebuilds meta/ with its own schema
        assert not (root / name).exists(), name
        assert (backup / name).exists(), name


@pytest.mark.slow
def test_split_and_merge_keep_provenance(recorded, tmp_path):
    source, repo_id = recorded
    _edit("--repo_id", repo_id, "--root", str(source), "--new_root", str(tmp_path / "splits"),
          "--operation.type", "split", "--operation.splits", '{"train": [0, 2], "val": [1, 3]}')
    train, val = tmp_path / "splits" / "train", tmp_path / "splits" / "val"
    assert [b for _, b in _provenance(train)] == [0, 2] and [b for _, b in _provenance(val)] == [1, 3]
    _edit("--new_repo_id", "local/merged", "--new_root", str(tmp_path / "merged"), "--operation.type", "merge",
          "--operation.repo_ids", f"['{repo_id}_val', '{repo_id}_train']",
          "--operation.roots", f"['{val}', '{train}']")
    merged = _joins(tmp_path / "merged", source)
    assert [r["benchmark_episode_index"] for r in merged.values()] == [1, 3, 0, 2]
    assert json.loads((tmp_path / "merged/meta/info.json").read_text())["robot_type"] == "synth_arm"
