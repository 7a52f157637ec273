"""A stand-in for a suite's published LeRobot dataset, written by LeRobot's own writer
(``LeRobotDataset.create`` + ``add_frame``), for the recording tests' merge checks."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def write_standin(root: Path, repo_id: str, features: dict, fps: int, robot_type: str, episodes: int, frames: int,
                  frame: Callable[[np.random.Generator, int], dict[str, Any]], seed: int) -> Path:
    """``episodes`` episodes of ``frames`` frames each, frame ``i`` being ``frame(rng, i)``."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset.create(repo_id=repo_id, fps=fps, features=features, root=root, robot_type=robot_type,
                               use_videos=True)
    rng = np.random.default_rng(seed)
    for _ in range(episodes):
        for i in range(frames):
            ds.add_frame(frame(rng, i))
        ds.save_episode()
    ds.finalize()
    return root
