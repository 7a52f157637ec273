"""The deterministic ``nav_v1`` benchmark: ``nav_to_obj`` in the ``nav_houses`` scenes on ``mobile_franka``.

``molmo-bench generate nav --houses 12 --episodes-per-house 5 --seed 0 --name nav_v1`` writes nav_v1.
Per episode: a house, a target object of the
house (its category's instances are the candidates; two categories per house have two, in different rooms; the
next object when no start reaches the drawn one's), and the robot's start: a floor cell a robot of
:data:`ROBOT_RADIUS` fits on, with a path to the ring :data:`GOAL_RING` around the nearest candidate, at least
:data:`MIN_START_DISTANCE` from every candidate (planar) and a path at least :data:`MIN_PATH` long, facing a
random yaw. The prompt is MolmoSpaces' (:func:`molmo_lerobot.tasks.nav_to_obj.nav_prompt`) with the
candidates' name (their category's where their names differ); ``succ_pos_threshold`` is their 1.5 m;
``cameras: []`` (the robot's camera system builds the head and wrist cameras). Same arguments, same JSON.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.generators import BenchmarkGenerator
from molmo_lerobot.benchmark.output import benchmark_metadata, rounded
from molmo_lerobot.benchmark.task_specs import NavToObjTaskSpec
from molmo_lerobot.content.libero.nav_houses import NavHouses, display_name
from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS
from molmo_lerobot.poses import yaw_quat
from molmo_lerobot.robots.mobile_franka import MobileFranka
from molmo_lerobot.sim.navigation import free_space, occupancy, path_lengths
from molmo_lerobot.tasks.nav_to_obj import nav_prompt

GENERATOR_VERSION = 1
TASK_CLS = "molmo_lerobot.tasks.nav_to_obj.NavToObjTask"
HORIZON_SEC = 45.0
IMG_RESOLUTION = (224, 224)
ROBOT = "mobile_franka"
#: the robot's footprint radius in its start pose (0.40 m) with room to spare, for start cells
ROBOT_RADIUS = 0.5
GOAL_RING = (0.55, 1.2)
MIN_START_DISTANCE, MIN_PATH = 2.5, 3.0
BASE_Z = 0.005  # their add_robot_to_scene lifts a planar pose by 5 mm


@cache
def _house(house: int) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray]:
    """The house's occupancy grid (without a robot), its free cells for the robot and cell centres."""
    model = NavHouses().build(house).compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    sx, sy = NavHouses().metadata(house)["size"]
    grid = occupancy(model, data, (-0.5, -0.5, sx + 0.5, sy + 0.5))
    xs, ys = grid.centres()
    return grid, free_space(grid, ROBOT_RADIUS), xs, ys


def _start(house: int, targets: np.ndarray, rng: np.random.Generator) -> tuple[float, float] | None:
    grid, free, xs, ys = _house(house)
    goals = np.zeros_like(free)
    for t in targets:
        r = np.hypot(xs - t[0], ys - t[1])
        goals |= (r >= GOAL_RING[0]) & (r <= GOAL_RING[1])
    dist = path_lengths(free, goals, grid.res)
    near = np.min([np.hypot(xs - t[0], ys - t[1]) for t in targets], axis=0)
    ok = np.isfinite(dist) & (dist >= MIN_PATH) & (near >= MIN_START_DISTANCE)
    cells = np.argwhere(ok)
    if len(cells) == 0:
        return None
    i, j = cells[int(rng.integers(len(cells)))]
    x, y = grid.centre(int(i), int(j))
    return float(x), float(y)


def _nav_episode(scene: NavHouses, house: int, index: int, seed: int) -> dict[str, Any]:
    rng = np.random.default_rng([seed, house, index, 0x4E])
    objects = scene.metadata(house)["objects"]
    uids = sorted(objects)
    first = index + int(rng.integers(len(uids)))
    for k in range(len(uids)):  # the drawn object, else the next one whose candidates a start reaches
        target = uids[(first + k) % len(uids)]
        category = objects[target]["category"]
        candidates = [u for u in uids if objects[u]["category"] == category]
        start = _start(house, np.array([objects[u]["default_pose"][:2] for u in candidates]), rng)
        if start is not None:
            break
    else:
        raise RuntimeError(f"nav_houses house {house}: no object has a start {MIN_START_DISTANCE} m away that "
                           "reaches it")
    x, y = start
    yaw = float(rng.uniform(-math.pi, math.pi))
    robot = MobileFranka()
    names = {LIBERO_OBJECTS[u].name for u in candidates}  # the object's name, or its category's if they differ
    name = names.pop() if len(names) == 1 else display_name(category)
    return {
        "house_index": house,
        "scene_dataset": scene.name,
        "data_split": "val",
        "seed": int(rng.integers(2**31 - 1)),
        "robot": {"robot_name": ROBOT, "init_qpos": {"base": [], "arm": list(robot.default_init_qpos["arm"]),
                                                     "gripper": [0.0]}},
        "img_resolution": list(IMG_RESOLUTION),
        "cameras": [],
        "scene_modifications": {"added_objects": {}, "object_poses": {}, "removed_objects": []},
        "task": {
            "task_cls": TASK_CLS,
            "task_type": "nav_to_obj",
            "robot_base_pose": [rounded(x), rounded(y), BASE_Z, *(rounded(q) for q in yaw_quat(yaw))],
            "pickup_obj_name": target,
            "pickup_obj_candidates": candidates,
            "pickup_obj_category": category,
            "succ_pos_threshold": NavToObjTaskSpec.model_fields["succ_pos_threshold"].default,
            "task_horizon_sec": HORIZON_SEC,
        },
        "task_relevant_objects": candidates,
        "language": {"task_description": nav_prompt(name, len(candidates)),
                     "referral_expressions": {"pickup_obj_name": name}},
    }


def generate_benchmark(n_houses: int, episodes_per_house: int, seed: int,
                       name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Episodes (JSON-ready EpisodeSpec dicts) and metadata, fully determined by the arguments."""
    if n_houses < 1 or episodes_per_house < 1:
        raise ValueError("generate_nav: n_houses and episodes_per_house must be at least 1")
    scene = NavHouses()
    houses = sorted(int(h) for h in np.random.default_rng([seed, 0x4855, 0x4E]).choice(scene.n_houses(), n_houses,
                                                                                         replace=False))
    episodes = [_nav_episode(scene, h, i, seed) for h in houses for i in range(episodes_per_house)]
    rooms = {h: len(scene.metadata(h)["rooms"]) for h in houses}
    description = (f"nav_to_obj in multi-room nav_houses: {n_houses} houses x {episodes_per_house} episodes, "
                   f"mobile_franka, head + wrist cameras (generator v{GENERATOR_VERSION}, seed {seed})")
    meta = benchmark_metadata(name, "nav_to_obj", description, episodes, houses, episodes_per_house, seed,
                              LIBERO_OBJECTS, GENERATOR_VERSION,
                              room_count_counts={str(n): list(rooms.values()).count(n)
                                                 for n in sorted(set(rooms.values()))})
    meta["camera_system_class"] = MobileFranka.default_camera_system
    return episodes, meta


def _generate(task: str, n_houses: int, episodes_per_house: int, seed: int,
              name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    return generate_benchmark(n_houses, episodes_per_house, seed, name)  # one task: nav_to_obj


@hookimpl
def molmo_generators() -> list[BenchmarkGenerator]:
    return [BenchmarkGenerator("nav", "nav_to_obj in multi-room nav_houses, mobile_franka", ("nav_to_obj",), _generate)]
