"""`make train-demo` (scripts/train_demo.sh) runs end to end at toy size on its default, state-only path:
expert recordings with ``observation.environment_state``, the cameras dropped, lerobot-train ACT on the
state features, both policies scored on pick_v1 (the checkpoint reading the environment state) and compared."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "train_demo.sh"


@pytest.mark.slow
def test_train_demo_state_recipe_runs_at_toy_size(tmp_path):
    env = {**os.environ, "PYTHON": sys.executable, "WORK": str(tmp_path / "demo"), "HOUSES": "1",
           "EPISODES_PER_HOUSE": "2", "STEPS": "2", "BATCH": "2", "DEVICE": "cpu", "EVAL_LIMIT": "1", "WORKERS": "1",
           "ACT_ARGS": "--policy.dim_model=64 --policy.dim_feedforward=128 --policy.n_encoder_layers=1"}
    proc = subprocess.run(["bash", str(SCRIPT)], env=env, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    work = tmp_path / "demo"
    recorded = json.loads((work / "expert" / "dataset" / "meta" / "info.json").read_text())["features"]
    assert recorded["observation.environment_state"]["names"][:3] == ["object_x", "object_y", "object_z"]
    assert recorded["observation.environment_state"]["names"][-3:] == [f"tcp_to_object_{c}" for c in "xyz"]
    trained_on = json.loads((work / "expert" / "dataset-state" / "meta" / "info.json").read_text())["features"]
    assert not [k for k in trained_on if k.startswith("observation.images.")]
    assert "observation.environment_state" in trained_on
    ckpt = work / "train" / "checkpoints" / "last" / "pretrained_model"
    inputs = json.loads((ckpt / "config.json").read_text())["input_features"]
    assert sorted(inputs) == ["observation.environment_state", "observation.state"]
    config = json.loads((ckpt / "config.json").read_text())
    assert config["normalization_mapping"]["ENV"] == "MEAN_STD"  # ACT's default leaves it in raw metres
    evaluated = json.loads((work / "eval-trained" / "results.json").read_text())
    assert evaluated["n_errors"] == 0 and evaluated["n_valid"] == 1  # the policy got its environment state
    summary = (work / "summary.txt").read_text().splitlines()
    assert [line.split()[0] for line in summary[:3]] == ["expert", "random", "trained"]
    assert summary[3].startswith("trained beats random with non-overlapping CIs: ")
    assert summary[4].startswith("policy inputs: state")
    assert "B: lerobot" in (work / "compare.txt").read_text()
