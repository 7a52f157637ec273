"""LeRobot's own push_to_hub and LeRobotDataset(repo_id) download, against the Hub stand-in."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.slow
def test_lerobot_push_and_download(hub_standin, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    features = {"observation.state": {"dtype": "float32", "shape": (3,), "names": ["a", "b", "c"]},
                "action": {"dtype": "float32", "shape": (2,), "names": ["x", "y"]}}
    ds = LeRobotDataset.create("me/standin_ds", fps=10, features=features, root=tmp_path / "ds", use_videos=False)
    for ep in range(2):
        for t in range(5):
            ds.add_frame({"observation.state": np.full(3, ep + t, np.float32), "action": np.zeros(2, np.float32),
                          "task": "pick the block"})
        ds.save_episode()
    ds.finalize()
    ds.push_to_hub()
    refs = hub_standin.repos[("dataset", "me/standin_ds")].tags
    assert list(refs) == ["v3.0"]
    back = LeRobotDataset("me/standin_ds", root=tmp_path / "download", video_backend="pyav")
    assert back.num_episodes == 2 and back.num_frames == 10
    assert float(back[7]["observation.state"][0]) == 1 + 2
