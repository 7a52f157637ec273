"""Run identity: the policy checkpoint's content hash is recorded, and resume refuses a retrained one."""

from __future__ import annotations

import json
import os

import pytest

from molmo_lerobot.errors import RunError
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.runner.fingerprint import checkpoint_sha256, policy_checkpoints


def _checkpoint(root, weights: bytes):
    root.mkdir(parents=True)
    (root / "model.safetensors").write_bytes(weights)
    (root / "config.json").write_text('{"type": "act"}')
    return root


def test_hash_covers_weights_and_config_and_follows_symlinks(tmp_path):
    a = _checkpoint(tmp_path / "a", b"w" * 100)
    first = checkpoint_sha256(a)
    assert first["n_files"] == 2 and first["bytes"] == 100 + len('{"type": "act"}')
    (a / "config.json").write_text('{"type": "diffusion"}')
    assert checkpoint_sha256(a)["sha256"] != first["sha256"]
    os.symlink(a, tmp_path / "last")
    assert checkpoint_sha256(tmp_path / "last")["sha256"] == checkpoint_sha256(a)["sha256"]
    assert policy_checkpoints({"name": "scripted"}) is None
    assert policy_checkpoints({"name": "lerobot", "path": "lerobot/act_aloha"}) == {
        "path": {"path": "lerobot/act_aloha", "sha256": None}}


def test_resume_refuses_a_retrained_checkpoint(faulty_policy, small_bench, tmp_path, eval_config, fork_servers):
    steps = tmp_path / "checkpoints"
    _checkpoint(steps / "001000", b"\x01" * 64)
    _checkpoint(steps / "002000", b"\x02" * 64)
    last = steps / "last"
    os.symlink(steps / "001000", last)
    out = tmp_path / "run"
    common = ["policy=faulty", "workers=1", "horizon=2", f"policy.marker_dir={faulty_policy.marker_dir}",
              f"+policy.path={last}"]
    first = run_evaluation(eval_config(small_bench, out, *common, "limit=1"), fork_servers)
    recorded = first.summary["policy_checkpoint"]["path"]
    assert recorded["sha256"] == checkpoint_sha256(steps / "001000")["sha256"]
    assert json.loads((out / "run.json").read_text())["policy_checkpoint"]["path"] == recorded

    last.unlink()
    os.symlink(steps / "002000", last)  # retrained: same path, new weights
    with pytest.raises(RunError, match="policy_checkpoint differs"):
        run_evaluation(eval_config(small_bench, out, *common, "limit=2", "resume=true"), fork_servers)
    last.unlink()
    os.symlink(steps / "001000", last)
    resumed = run_evaluation(eval_config(small_bench, out, *common, "limit=2", "resume=true"), fork_servers)
    assert resumed.summary["n_episodes"] == 2
