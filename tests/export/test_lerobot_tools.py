"""LeRobot's own tools on our recordings: the video backend LeRobot picks loads, lerobot-dataset-viz works."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import export_synthetic as S  # tests/export is on sys.path (pytest's prepend import mode)
import numpy as np
import pytest

from molmo_lerobot.export.recorder import LeRobotRecorderFactory
from molmo_lerobot.run_config import RunConfig

CFG = {"benchmark": {"name": "synth_v1"}, "policy": {"name": "scripted"},
       "timing": {"policy_dt_ms": 66.0}, "hub": {"repo_id": None, "private": False}, "push": False}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(CFG))
    w = factory.make("w0g0", out)
    results = [S.run_episode(w, i, 6, success_from=3) for i in range(2)]
    w.close()
    factory.finalize(out, results, S.summary_for(results))
    return out / "dataset", factory.repo_id


def _outside_this_venv(spec) -> bool:
    return not Path(spec.origin).resolve().is_relative_to(Path(sys.prefix).resolve())


def test_the_video_backend_lerobot_picks_loads_and_decodes_our_videos(recorded):
    """``make .venv`` leaves torchcodec installed only where it loads; LeRobot then never falls back."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.utils.import_utils import get_safe_default_video_backend

    backend = get_safe_default_video_backend()
    root, repo_id = recorded
    ds = LeRobotDataset(repo_id, root=root)  # LeRobot's default backend, as its tools use it
    assert ds._video_backend == backend
    frame = ds[7]  # episode 1, step 1: brightness encodes (episode, step)
    level = (1 * 37 + 1 * 5) % 250 / 255.0
    assert float(np.asarray(frame["observation.images.exo"]).mean()) == pytest.approx(level, abs=0.03)
    spec = importlib.util.find_spec("torchcodec")
    if spec is not None:
        try:
            importlib.import_module("torchcodec")
        except (ImportError, OSError, RuntimeError):
            if _outside_this_venv(spec):
                pytest.skip(f"torchcodec comes from {spec.origin}, a venv `make .venv` does not manage here")
            pytest.fail("torchcodec is installed but cannot load: "
                        "run `make .venv` (it removes it so LeRobot uses PyAV)")


def test_lerobot_dataset_viz_saves_a_recording_of_our_episode(recorded, tmp_path):
    pytest.importorskip("rerun", reason="lerobot[viz] (the `viz` extra that make .venv installs)")
    root, repo_id = recorded
    proc = subprocess.run(
        [sys.executable, "-m", "lerobot.scripts.lerobot_dataset_viz", "--repo-id", repo_id, "--root", str(root),
         "--episode-index", "1", "--save", "1", "--output-dir", str(tmp_path), "--num-workers", "0"],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    rrd = list(tmp_path.glob("*.rrd"))
    assert len(rrd) == 1 and rrd[0].stat().st_size > 10_000, proc.stderr[-2000:]


def test_our_default_recording_merges_with_a_dataset_made_on_lerobots_defaults(recorded, tmp_path):
    """LeRobot's merge refuses datasets whose ``video.codec`` differ: ours must be LeRobot's default."""
    from lerobot.datasets.dataset_tools import merge_datasets
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.utils.constants import DEFAULT_FEATURES

    root, repo_id = recorded
    ours = LeRobotDataset(repo_id, root=root, video_backend="pyav")
    features = {k: v for k, v in ours.meta.features.items() if k not in DEFAULT_FEATURES}
    for feature in features.values():
        feature.pop("info", None)  # what a user declares: dtype, shape, names
    theirs = LeRobotDataset.create("someone/synth-teleop", fps=ours.fps, features=features,
                                   root=tmp_path / "theirs", robot_type=ours.meta.robot_type)
    for t in range(4):
        frame = S.obs(7, t)
        theirs.add_frame({**{f"observation.images.{c}": img for c, img in frame["images"].items()},
                          "observation.state": np.array([7, t, 0.5, 0.01, 0.01], np.float32),
                          "action": np.zeros(4, np.float32), "next.success": np.array([False]),
                          "next.done": np.array([t == 3]), "eval.episode_index": np.array([-1]),
                          "eval.seed": np.array([-1]), "task": "pick up the mug"})
    theirs.save_episode()
    theirs.finalize()
    merged = merge_datasets([ours, LeRobotDataset("someone/synth-teleop", root=tmp_path / "theirs",
                                                  video_backend="pyav")],
                            output_repo_id="someone/merged", output_dir=tmp_path / "merged")
    assert merged.num_episodes == ours.num_episodes + 1 and len(merged) == len(ours) + 4
    assert merged.meta.features["observation.images.exo"]["info"]["video.codec"] == "av1"
    last = merged[len(merged) - 1]
    assert float(last["observation.state"][1]) == 3.0
