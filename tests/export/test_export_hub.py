"""Hub publishing against the local stand-in: round trip, and a failed push keeps local files."""

from __future__ import annotations

import logging

import export_synthetic as S  # tests/export is on sys.path (pytest's prepend import mode)
import numpy as np
import pytest

from molmo_lerobot.export.hub import push_dataset
from molmo_lerobot.export.recorder import LeRobotRecorderFactory
from molmo_lerobot.results import Push
from molmo_lerobot.run_config import RunConfig

CFG = {"benchmark": {"name": "synth_v1"}, "policy": {"name": "scripted"}, "timing": {"policy_dt_ms": 66.0},
       "hub": {"repo_id": "molmo-test/synth-rollouts", "private": True}, "push": True}


@pytest.fixture
def hub(hub_standin):
    """The stand-in Hub (it also answers the client's README metadata check)."""
    return hub_standin


def _record(out, factory):
    w = factory.make("w0g0", out)
    results = [S.run_episode(w, 0, 6, success_from=2), S.run_episode(w, 1, 5, success_from=None)]
    w.close()
    return results


def _snapshot(root):
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_push_then_load_from_the_hub_gives_the_same_frames(hub, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    results = _record(tmp_path / "run", factory)
    pushed = factory.finalize(tmp_path / "run", results, S.summary_for(results))  # merges and pushes
    assert pushed == Push(repo_id=factory.repo_id, ok=True, error=None)
    local = LeRobotDataset(factory.repo_id, root=tmp_path / "run" / "dataset", video_backend="pyav")
    remote = LeRobotDataset(factory.repo_id, root=tmp_path / "download", video_backend="pyav")
    assert remote.num_episodes == local.num_episodes == 2 and len(remote) == len(local) == 11
    for i in (0, 5, 10):
        a, b = local[i], remote[i]
        for key in ("observation.state", "action", "next.success", "observation.images.exo"):
            assert np.array_equal(np.asarray(a[key]), np.asarray(b[key])), key
    # the scores and eval records travel with the dataset
    for name in ("results.json", "meta/eval/episodes.jsonl", "README.md"):
        assert (tmp_path / "download" / name).read_bytes() == (tmp_path / "run" / "dataset" / name).read_bytes()
    card = (tmp_path / "download" / "README.md").read_text()
    assert "success (end)" in card
    assert f"huggingface.co/spaces/lerobot/visualize_dataset?path={factory.repo_id}" in card  # on the Hub: its viewer


def test_failed_push_warns_and_keeps_local_files(tmp_path, monkeypatch, caplog):
    import huggingface_hub.constants as hfc

    secret = "hf_" + "x" * 30
    monkeypatch.setenv("HF_TOKEN", secret)
    monkeypatch.setattr(hfc, "ENDPOINT", "http://127.0.0.1:9")  # nothing listens on the discard port
    monkeypatch.setattr(hfc, "HF_HUB_OFFLINE", False)
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    out = tmp_path / "run"
    results = _record(out, factory)
    factory.push = False
    factory.finalize(out, results, S.summary_for(results))
    before = _snapshot(out)
    with caplog.at_level(logging.WARNING):
        error = push_dataset(out / "dataset", factory.repo_id, private=True)
    assert error and secret not in error
    assert "local files are intact" in caplog.text and secret not in caplog.text
    assert _snapshot(out) == before


@pytest.mark.parametrize("private", [True, False])
def test_push_respects_private(hub, tmp_path, private):
    from huggingface_hub import HfApi

    factory = LeRobotRecorderFactory.from_config(RunConfig.of({**CFG, "hub": {**CFG["hub"], "private": private}}))
    results = _record(tmp_path / "run", factory)
    factory.finalize(tmp_path / "run", results, S.summary_for(results))
    assert HfApi().dataset_info(factory.repo_id).private is private


def test_a_refused_commit_is_recorded_in_the_summary(hub, tmp_path):
    hub.fail_commits = 500
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    out = tmp_path / "run"
    results = _record(out, factory)
    pushed = factory.finalize(out, results, S.summary_for(results))
    assert pushed is not None and pushed.ok is False and "500" in str(pushed.error)
    assert (out / "dataset" / "meta" / "info.json").is_file() and (out / "dataset" / "results.json").is_file()
