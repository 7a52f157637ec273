"""franka_droid variants of the shipped v1 benchmarks (the published files never change).

Each episode keeps its scene, objects and task; the robot becomes ``franka_droid`` with
MolmoSpaces' ``init_qpos`` conventions (gripper driver radians, open) and the arm pose of the
original episode with the wrist turned so the Robotiq sits like the Panda hand did;
``cameras: []`` so the DROID camera system builds the cameras. ``franka_droid`` stands on
MolmoSpaces' pedestal (``base_size`` z = 0.58 m), so the base pose is lowered by the pedestal's
height: the arm's root stays where the Panda's was, as in MolmoSpaces' scenes, where the base
pose is on the floor and the pedestal lifts the arm to the table.

``python tests/tasks/droid_variants.py OUT_DIR`` writes ``OUT_DIR/<name>_droid/benchmark.json``
for every v1 benchmark (for ``molmo-eval benchmark.path=...``).
"""

from __future__ import annotations

import copy
import json
import math
import sys
from pathlib import Path

from molmo_lerobot.paths import data_path
from molmo_lerobot.robots.franka_droid import BASE_SIZE

V1 = ("pick_v1", "pick_and_place_v1", "next_to_v1", "color_v1", "open_v1", "close_v1")
#: MolmoSpaces' open gripper (driver joint radians)
OPEN_DRIVERS = [0.00296, 0.00296]


def on_pedestal(episode: dict) -> dict:
    """``episode`` (a copy) with its base pose lowered by franka_droid's pedestal: the arm's root stays put."""
    out = copy.deepcopy(episode)
    pose = list(out["task"]["robot_base_pose"])
    pose[2] = round(pose[2] - BASE_SIZE[2], 5)
    out["task"]["robot_base_pose"] = pose
    return out


def droid_episode(episode: dict) -> dict:
    out = on_pedestal(episode)
    arm = list(out["robot"]["init_qpos"]["arm"])
    arm[6] -= math.pi / 4  # the Panda hand is mounted -45° about the flange, the Robotiq at 0°
    out["robot"] = {"robot_name": "franka_droid", "init_qpos": {"base": [], "arm": arm, "gripper": OPEN_DRIVERS}}
    out["cameras"] = []
    return out


def droid_benchmark(name: str) -> list[dict]:
    episodes = json.loads((data_path("benchmarks") / name / "benchmark.json").read_text())
    return [droid_episode(e) for e in episodes]


def write_all(out_dir: Path) -> list[Path]:
    paths = []
    for name in V1:
        d = out_dir / f"{name}_droid"
        d.mkdir(parents=True, exist_ok=True)
        (d / "benchmark.json").write_text(json.dumps(droid_benchmark(name), indent=1))
        paths.append(d)
    return paths


if __name__ == "__main__":
    for p in write_all(Path(sys.argv[1])):
        print(p)
