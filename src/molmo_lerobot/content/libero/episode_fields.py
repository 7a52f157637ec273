"""What every v2 tabletop episode (pick, the place tasks, open/close) holds before its task: the robot
(franka_droid on its pedestal, started near :data:`READY_ARM`), the DROID cameras at 224², the house and
the episode seed. Both v2 generators (``libero.generate``, ``libero.generate_articulated``) build their
episodes on :func:`episode_fields`."""

from __future__ import annotations

from typing import Any

import numpy as np

from molmo_lerobot.benchmark.output import rounded

IMG_RESOLUTION = (224, 224)
ROBOT = "franka_droid"
CAMERA_SYSTEM = "FrankaDroidCameraSystem"
#: TCP 0.45 m ahead of the base, 1.02 m above the floor, pointing down (IK on franka_droid on its pedestal)
READY_ARM = (0.0, -0.345, 0.0, -2.044, 0.0, 1.699, 0.0)


def start_arm(rng: np.random.Generator) -> np.ndarray:
    """The episode's arm start: :data:`READY_ARM` with up to 0.05 rad of jitter per joint."""
    return np.asarray(READY_ARM) + rng.uniform(-0.05, 0.05, 7)


def episode_fields(scene_name: str, house: int, rng: np.random.Generator, arm: np.ndarray,
                   object_poses: dict[str, list[float]]) -> dict[str, Any]:
    """House, scene, the episode seed (drawn from ``rng`` now), the robot's start pose ``arm``, the
    cameras (the camera system's) and the object poses the scene starts from."""
    return {
        "house_index": house,
        "scene_dataset": scene_name,
        "data_split": "val",
        "seed": int(rng.integers(2**31 - 1)),
        "robot": {"robot_name": ROBOT, "init_qpos": {"arm": [rounded(q) for q in arm], "gripper": [0.0]}},
        "img_resolution": list(IMG_RESOLUTION),
        "cameras": [],
        "scene_modifications": {"added_objects": {}, "object_poses": object_poses, "removed_objects": []},
    }
