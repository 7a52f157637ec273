"""`make train-demo` (scripts/train_demo.sh) runs end to end at toy size: expert recordings,
lerobot-train ACT, both policies scored on pick_v1 and compared."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "train_demo.sh"


@pytest.mark.slow
def test_train_demo_recipe_runs_at_toy_size(tmp_path):
    env = {**os.environ, "PYTHON": sys.executable, "WORK": str(tmp_path / "demo"), "HOUSES": "1",
           "EPISODES_PER_HOUSE": "2", "STEPS": "2", "BATCH": "2", "DEVICE": "cpu", "EVAL_LIMIT": "1", "WORKERS": "1",
           "ACT_ARGS": "--policy.dim_model=64 --policy.dim_feedforward=128 --policy.n_encoder_layers=1"}
    proc = subprocess.run(["bash", str(SCRIPT)], env=env, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    work = tmp_path / "demo"
    assert (work / "train" / "checkpoints" / "last" / "pretrained_model" / "model.safetensors").is_file()
    summary = (work / "summary.txt").read_text().splitlines()
    assert [line.split()[0] for line in summary[:3]] == ["expert", "random", "trained"]
    assert summary[3].startswith("trained beats random with non-overlapping CIs: ")
    assert "B: lerobot" in (work / "compare.txt").read_text()
