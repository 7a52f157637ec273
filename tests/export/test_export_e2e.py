"""End to end on pick_v1: a multi-worker recorded eval (default run), the report, and the
eval → train → eval loop (slow)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from molmo_lerobot.config import compose
from molmo_lerobot.export.merge import read_eval_records
from molmo_lerobot.export.report import write_report
from molmo_lerobot.runner.evaluate import run_evaluation

REPO_ID = "local/pick_v1-scripted"


def test_multi_worker_recording_loads_and_agrees_with_episodes_jsonl(pick_recording):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    out, res, shards = pick_recording
    episodes = {e["episode_index"]: e for e in map(json.loads, (out / "episodes.jsonl").read_text().splitlines())}
    ds = LeRobotDataset(REPO_ID, root=out / "dataset", video_backend="pyav")
    records = read_eval_records(out / "dataset")
    assert [r["benchmark_episode_index"] for r in records] == sorted(episodes)
    stored = [r for r in records if r["episode_index"] is not None]
    assert ds.num_episodes == len(stored) == sum(e["error"] is None for e in episodes.values()) == 4
    assert ds.fps == 15 and set(ds.meta.video_keys) == {"observation.images.exterior", "observation.images.wrist"}
    for rec in stored:
        ep = ds.meta.episodes[rec["episode_index"]]
        last = ds[ep["dataset_to_index"] - 1]
        truth = episodes[rec["benchmark_episode_index"]]
        assert bool(last["next.success"]) == truth["success"] == rec["success"]
        assert ep["length"] == truth["steps"] == 30
        assert last["task"] == truth["prompt"]
        assert rec["seed"] == truth["seed"] and rec["benchmark_sha256"] == res.summary["benchmark"]["sha256"]
    assert json.loads((out / "dataset" / "results.json").read_text())["n_episodes"] == 4
    assert not (out / "dataset_shards").exists()
    # two workers finish in any order; the dataset still follows the benchmark, and names the robot
    assert [(r["episode_index"], r["benchmark_episode_index"]) for r in stored] == [(i, i) for i in range(4)]
    firsts = [int(ds.meta.episodes[i]["dataset_from_index"]) for i in range(4)]
    assert [int(ds[first]["eval.episode_index"]) for first in firsts] == [0, 1, 2, 3]
    assert shards < 4  # workers play stretches of consecutive episodes into one shard, not one shard per episode
    assert json.loads((out / "dataset" / "meta" / "info.json").read_text())["robot_type"] == "franka"
    page = write_report(out, res.run_summary, res.episodes).read_text()
    assert page.count("<video") == 8


def test_a_dataset_about_to_be_pushed_names_no_path_of_this_machine(pick_recording, hub_standin, tmp_path_factory,
                                                                    tmp_path):
    """Every file pushed (and every file of the local dataset) is free of the run's, the temp
    dir's, the home dir's and the repository's absolute paths, which the run config holds."""
    from huggingface_hub import snapshot_download

    import molmo_lerobot
    from molmo_lerobot.export.hub import push_dataset

    out, res, _ = pick_recording
    assert str(out) in json.dumps(res.summary)  # the run's own summary names them; the dataset must not
    assert push_dataset(out / "dataset", REPO_ID.replace("local/", "molmo-test/")) is None
    pushed = Path(snapshot_download(REPO_ID.replace("local/", "molmo-test/"), repo_type="dataset",
                                    local_dir=tmp_path / "pushed"))
    places = {Path(molmo_lerobot.__file__).parents[2], Path.home(), tmp_path_factory.getbasetemp(), out, Path.cwd()}
    needles = {str(p).encode() for place in places for p in (place, place.resolve())}
    files = [p for root in (out / "dataset", pushed) for p in root.rglob("*")
             if p.is_file() and ".cache" not in p.parts]
    assert len(files) > 10 and any(p.name == "results.json" for p in files)
    leaks = [(str(p), n.decode()) for p in files for n in needles if n in p.read_bytes()]
    assert not leaks, leaks
    shared = json.loads((pushed / "results.json").read_text())
    assert shared["output_dir"] == "." and shared["benchmark"]["path"] == "<local>/pick_v1"
    assert shared["benchmark"]["sha256"] == res.summary["benchmark"]["sha256"]


def readme_command(program: str, section: str = "### LeRobot's tools on the dataset") -> list[str]:
    """The first ``program`` command of README.md's bash blocks from ``section`` on, as its arguments
    (continuations joined)."""
    import re
    import shlex

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    readme = readme[readme.index(section):]
    for block in re.findall(r"```bash\n(.*?)```", readme, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            if line.startswith(program + " "):
                return shlex.split(line, comments=True)
    raise AssertionError(f"README.md has no `{program}` command in a bash block")


@pytest.mark.slow
def test_the_readme_lerobot_train_command_trains_on_the_export_and_its_checkpoint_evaluates(pick_recording, tmp_path):
    """README.md's copy-paste ``lerobot-train`` command, offline, on our recording: only its
    paths and step counts are replaced."""
    out, _, _ = pick_recording
    train = tmp_path / "train"
    cmd = readme_command("lerobot-train")
    assert f"--dataset.repo_id={REPO_ID}" in cmd
    overrides = {"--dataset.root": out / "dataset", "--output_dir": train, "--steps": 2, "--save_freq": 2}
    keys = [arg.split("=", 1)[0] for arg in cmd]
    assert set(overrides) <= set(keys), f"README's command lacks {set(overrides) - set(keys)}"
    cmd = [str(Path(sys.executable).parent / cmd[0])] + [
        f"{key}={overrides[key]}" if key in overrides else arg for key, arg in zip(keys[1:], cmd[1:], strict=True)]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl"}
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    ckpt = train / "checkpoints" / "last" / "pretrained_model"
    assert (ckpt / "model.safetensors").is_file() and (ckpt / "config.json").is_file()

    res = run_evaluation(compose(["policy=lerobot", f"policy.path={ckpt}", "policy.device=cpu", "benchmark=pick_v1",
                                  "workers=1", "limit=1", "horizon=5", "progress=false",
                                  f"output_dir={tmp_path / 'eval'}"]))
    assert res.summary["n_episodes"] == 1 and res.summary["n_errors"] == 0, res.summary["errors"]
