"""Deterministic door-opening benchmarks in the ``door_rooms`` houses (``mobile_franka``).

``molmo-bench generate door --houses 12 --episodes-per-house 5 --seed 0 --name door_v1`` writes
door_v1. Per episode: a house, the side of the
door the robot starts on (alternating along the house's episodes, so each house has push and pull
episodes), and the robot's start pose sampled as MolmoSpaces' door sampler samples it
(``DoorOpeningTaskSamplerConfig``): 1.0–1.5 m from the handle on that side, facing it within ±0.25
rad, clear of the wall, of the door's swing and of the rooms' walls, and where their push / pull test
(made from the handle's motion as seen from the base) agrees with the side of the swing. The task is MolmoSpaces'
``DoorOpeningTask`` with their defaults written out (hinge range, reset state 0, threshold 0.67);
the prompt is their push / pull prompt (:func:`molmo_lerobot.tasks.door_opening.is_pushing`).
``cameras: []``: the robot's camera system builds them. Same arguments, same JSON.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.generators import BenchmarkGenerator
from molmo_lerobot.benchmark.output import rounded
from molmo_lerobot.benchmark.task_specs import DoorOpeningTaskSpec
from molmo_lerobot.content.doors.scenes import DOOR_NAME, DoorRooms, door_geometry
from molmo_lerobot.poses import yaw_quat
from molmo_lerobot.tasks.door_opening import PULL_PROMPT, PUSH_PROMPT, is_pushing

GENERATOR_VERSION = 1
TASK_CLS = "molmo_spaces.tasks.opening_tasks.DoorOpeningTask"
#: the generator's name in the metadata it writes: its module's path when door_v1 was published
#: (``molmo_lerobot.doors.generate``), kept so that regenerating door_v1 gives the published bytes
GENERATOR_ID = "molmo_lerobot.doors.generate"
HORIZON_SEC = 40.0  # MolmoSpaces' door config: 400 steps at 100 ms
ROBOT = "mobile_franka"
IMG_RESOLUTION = (224, 224)
#: MolmoSpaces' franka init_qpos (MobileFrankaRobotConfig / franka_droid), jittered per episode
READY_ARM = (0.0, -0.7854, 0.0, -2.3562, 0.0, 1.5708, 0.7854)
#: their sampler: radius around the handle, yaw noise about facing it
RADIUS = (1.0, 1.5)
YAW_NOISE = 0.25
#: clearances of the base centre: from the dividing wall, from the door's swing circle, from the rooms' walls
WALL_CLEARANCE, SWING_CLEARANCE, ROOM_CLEARANCE = 0.5, 0.45, 0.6


@cache
def _door_model(house: int) -> mujoco.MjModel:
    return DoorRooms().build(house).compile()


def _handle(door: dict[str, Any]) -> np.ndarray:
    """The handle bar's position (either face: the centre line of the leaf) with the door closed."""
    return np.array([0.0, door["hinge"][1] + door["leaf_dir"] * door["handle_radius"], door["handle_z"]])


def start_pose(house: int, side: int, rng: np.random.Generator) -> list[float]:
    """A base pose on ``side`` (±1 along x) of the wall, 1.0–1.5 m from the handle, facing it."""
    door = door_geometry(house)
    meta = DoorRooms().metadata(house)
    handle, hinge = _handle(door), np.array(door["hinge"])
    (x_lo, x_hi), (y_lo, y_hi) = meta["room_extent"]["x"], meta["room_extent"]["y"]
    for _ in range(200):
        r = float(rng.uniform(*RADIUS))
        a = float(rng.uniform(-math.pi / 3, math.pi / 3)) + (0.0 if side > 0 else math.pi)
        p = handle[:2] + r * np.array([math.cos(a), math.sin(a)])
        if side * p[0] < WALL_CLEARANCE or not (x_lo + ROOM_CLEARANCE < p[0] < x_hi - ROOM_CLEARANCE) \
                or not (y_lo + ROOM_CLEARANCE < p[1] < y_hi - ROOM_CLEARANCE):
            continue
        if side == door["swing_side"] and np.linalg.norm(p - hinge[:2]) < door["leaf_width"] + SWING_CLEARANCE:
            continue
        to_handle = handle[:2] - p
        yaw = math.atan2(to_handle[1], to_handle[0]) + float(rng.uniform(-YAW_NOISE, YAW_NOISE))
        pose = [rounded(p[0]), rounded(p[1]), 0.0, *(rounded(q) for q in yaw_quat(yaw))]
        if (prompt(house, pose) == PUSH_PROMPT) == (side != door["swing_side"]):  # their prompt tells the truth
            return pose
    raise RuntimeError(f"door_rooms house {house}: no start pose on side {side}")


def prompt(house: int, base_pose: list[float]) -> str:
    """MolmoSpaces' prompt for a robot at ``base_pose`` in ``house`` (door closed)."""
    model = _door_model(house)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    return PUSH_PROMPT if is_pushing(model, data, model.body(DOOR_NAME).id, np.array(base_pose[:3])) else PULL_PROMPT


def _episode(house: int, index: int, seed: int) -> dict[str, Any]:
    rng = np.random.default_rng([seed, house, index, 0xD0])
    side = 1 if (house + index) % 2 == 0 else -1
    base = start_pose(house, side, rng)
    arm = np.asarray(READY_ARM) + rng.uniform(-0.05, 0.05, 7)
    door = door_geometry(house)
    text = prompt(house, base)
    return {
        "house_index": house,
        "scene_dataset": DoorRooms.name,
        "data_split": "val",
        "seed": int(rng.integers(2**31 - 1)),
        "robot": {"robot_name": ROBOT, "init_qpos": {"base": [], "arm": [rounded(q) for q in arm], "gripper": [0.0]}},
        "img_resolution": list(IMG_RESOLUTION),
        "cameras": [],
        "scene_modifications": {"added_objects": {}, "object_poses": {}, "removed_objects": []},
        "task": {
            "task_cls": TASK_CLS,
            "task_type": "door_opening",
            "robot_base_pose": base,
            "door_body_name": DOOR_NAME,
            "articulated_joint_range": [rounded(v) for v in door["range"]],
            "articulated_joint_reset_state": [0.0],
            "door_openness_threshold": DoorOpeningTaskSpec.model_fields["door_openness_threshold"].default,
            "task_horizon_sec": HORIZON_SEC,
        },
        "task_relevant_objects": [DOOR_NAME],
        "language": {"task_description": text, "referral_expressions": {"door_body_name": "the door"}},
    }


def generate_benchmark(n_houses: int, episodes_per_house: int, seed: int,
                       name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Door-opening episodes (JSON-ready EpisodeSpec dicts) and metadata, fully determined by the arguments."""
    if n_houses < 1 or episodes_per_house < 1:
        raise ValueError("generate: n_houses and episodes_per_house must be at least 1")
    order = np.random.default_rng([seed, 0x4855, 0xD0]).permutation(DoorRooms().n_houses())
    houses = sorted(int(h) for h in order[:n_houses])
    episodes = [_episode(h, i, seed) for h in houses for i in range(episodes_per_house)]
    prompts = [e["language"]["task_description"] for e in episodes]
    metadata = {
        "name": name,
        "description": (f"open the door between two rooms: {n_houses} door_rooms houses x {episodes_per_house} "
                        f"episodes, mobile_franka starting 1.0-1.5 m from the handle on either side "
                        f"(generator v{GENERATOR_VERSION}, seed {seed})"),
        "num_episodes": len(episodes),
        "num_houses": len(houses),
        "task_cls_counts": {TASK_CLS: len(episodes)},
        "prompt_counts": {p: prompts.count(p) for p in sorted(set(prompts))},
        "robot_counts": {ROBOT: len(episodes)},
        "house_counts": {str(h): episodes_per_house for h in houses},
        "generator": {"module": GENERATOR_ID, "n_houses": len(houses),
                      "episodes_per_house": episodes_per_house, "seed": seed, "version": GENERATOR_VERSION},
    }
    return episodes, metadata


def _generate(task: str, n_houses: int, episodes_per_house: int, seed: int,
              name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    return generate_benchmark(n_houses, episodes_per_house, seed, name)  # one task: door_opening


@hookimpl
def molmo_generators() -> list[BenchmarkGenerator]:
    return [BenchmarkGenerator("door", "open the door between two door_rooms rooms, mobile_franka", ("door_opening",),
                               _generate)]
