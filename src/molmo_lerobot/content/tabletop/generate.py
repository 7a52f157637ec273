"""Deterministic benchmark generation on the procedural tabletop (``molmo-bench generate``).

``generate_benchmark`` draws houses and, per episode, a collision-free layout of every
house object inside the robot's workspace, the object to pick, the robot's start pose
(small joint jitter) and the exocentric camera (small jitter). The pick-and-place family
(``pick_and_place``, ``pick_and_place_next_to``, ``pick_and_place_color``) also brings one
or two of the house's receptacles into the workspace and picks the one to place at (next
to); the colour task repaints two receptacles of one category in distinct colours. The
same arguments always give the same episodes (byte-identical JSON).
"""

from __future__ import annotations

import importlib
import math
from collections import Counter
from typing import Any

import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.assets.builtin import (
    BUILTIN_OBJECTS,
    BUILTIN_RECEPTACLES,
    PAINT_COLORS,
    BuiltinObject,
    BuiltinReceptacle,
)
from molmo_lerobot.benchmark.generators import BenchmarkGenerator
from molmo_lerobot.benchmark.output import benchmark_metadata, rounded
from molmo_lerobot.content.tabletop.scene import ProceduralTabletop, ProceduralTabletopReceptacles
from molmo_lerobot.poses import look_rotation, mat_to_quat, quat_mul, yaw_quat
from molmo_lerobot.robots.franka import Franka

GENERATOR_VERSION = 1
TASK_CLS = {"pick": "molmo_lerobot.tasks.pick.PickTask",
            "pick_and_place": "molmo_lerobot.tasks.pick_and_place.PickAndPlaceTask",
            "pick_and_place_next_to": "molmo_lerobot.tasks.pick_and_place.PickAndPlaceNextToTask",
            "pick_and_place_color": "molmo_lerobot.tasks.pick_and_place.PickAndPlaceColorTask"}
PLACE_HORIZON_SEC = 40.0
#: next-to episodes start with the object's bounding circle at least this far from the receptacle's
NEXT_TO_START_GAP = 0.12
#: extra free space around the object to pick in place episodes (room for the open hand)
PICK_CLEARANCE = 0.04
#: free disc kept beside the receptacle in next-to episodes: object footprint + this margin
NEXT_TO_SPOT_MARGIN = 0.03
IMG_RESOLUTION = (224, 224)
#: free space kept between the bounding circles of neighbouring objects (room for fingers)
MIN_GAP = 0.05
_MAX_TRIES = 200


def _resting(obj: BuiltinObject, yaw: float) -> tuple[list[float], float, float]:
    """Orientation of ``obj`` resting on a table, its footprint radius and its centre height."""
    hx, hy, hz = obj.half_extents
    if obj.shape == "capsule":  # lies on its side: local z along world x, then yaw
        lie = [math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0]
        return quat_mul(yaw_quat(yaw), lie), math.hypot(hz, hx), hx
    return yaw_quat(yaw), math.hypot(hx, hy), hz


def _layout(objects: list[BuiltinObject], region: dict[str, Any], rng: np.random.Generator) -> dict[str, list[float]]:
    """Poses for every object inside ``region``, footprints at least MIN_GAP apart."""
    for _ in range(_MAX_TRIES):
        placed: list[tuple[float, float, float]] = []
        poses: dict[str, list[float]] = {}
        for obj in objects:
            yaw = float(rng.uniform(-math.pi, math.pi))
            quat, radius, height = _resting(obj, yaw)
            for _ in range(50):
                x = float(rng.uniform(*region["x"]))
                y = float(rng.uniform(*region["y"]))
                if all(math.hypot(x - px, y - py) >= radius + pr + MIN_GAP for px, py, pr in placed):
                    break
            else:
                break
            placed.append((x, y, radius))
            poses[obj.uid] = [rounded(x), rounded(y), rounded(region["z"] + height)] + [rounded(q) for q in quat]
        if len(poses) == len(objects):
            return poses
    raise RuntimeError(f"could not place {len(objects)} objects in {region} after {_MAX_TRIES} tries")


def tabletop_cameras(table_height: float, rng: np.random.Generator) -> list[dict[str, Any]]:
    """An exocentric camera beside the table (jittered) and a wrist camera on the hand."""
    eye = np.array([1.3, -0.6, table_height + 0.7]) + rng.uniform(-0.03, 0.03, 3)
    target = np.array([0.38, 0.0, table_height + 0.12])
    forward = target - eye
    exo = {"name": "exterior", "type": "exocentric", "pos": [rounded(v) for v in eye], "up": [0.0, 0.0, 1.0],
           "forward": [rounded(v) for v in forward / np.linalg.norm(forward)], "fov": 55.0, "record_depth": False}
    # wrist camera in link 7's frame: beside the hand, across the finger axis, looking past the fingertips
    side = np.array([math.sqrt(0.5), -math.sqrt(0.5), 0.0])
    offset = 0.075 * side + np.array([0.0, 0.0, 0.12])
    lookat = np.array([0.0, 0.0, 0.32])
    quat = mat_to_quat(look_rotation(lookat - offset, side))
    wrist = {"name": "wrist", "type": "robot_mounted", "reference_body_names": ["panda0_link7"],
             "camera_offset": [rounded(v) for v in offset], "lookat_offset": [rounded(v) for v in lookat],
             "camera_quaternion": [rounded(q) for q in quat], "fov": 75.0, "record_depth": False}
    return [exo, wrist]


def episode_base(house: int, scene_dataset: str, seed: int, robot: Franka, arm: np.ndarray,
                 cameras: list[dict[str, Any]], poses: dict[str, list[float]]) -> dict[str, Any]:
    """The fields every generated episode has before its ``task``, in schema order."""
    return {
        "house_index": house,
        "scene_dataset": scene_dataset,
        "data_split": "val",
        "seed": seed,
        "robot": {"robot_name": robot.name,
                  "init_qpos": {"arm": [rounded(q) for q in arm], "gripper": list(robot.default_init_qpos["gripper"])}},
        "img_resolution": list(IMG_RESOLUTION),
        "cameras": cameras,
        "scene_modifications": {"added_objects": {}, "object_poses": poses, "removed_objects": []},
    }


def _episode(scene: ProceduralTabletop, house: int, index: int, seed: int, task: str) -> dict[str, Any]:
    rng = np.random.default_rng([seed, house, index])
    meta = scene.metadata(house)
    objects = [BUILTIN_OBJECTS[o["asset_id"]] for o in meta["objects"].values() if not o["receptacle"]]
    poses = _layout(objects, meta["placement_region"], rng)
    target = objects[int(rng.integers(len(objects)))]
    robot = Franka()
    arm = np.asarray(robot.default_init_qpos["arm"]) + rng.uniform(-0.05, 0.05, 7)
    phrase = f"the {target.color} {target.category}"
    # arguments are evaluated in order: the episode seed is drawn before the cameras
    return {
        **episode_base(house, scene.name, int(rng.integers(2**31 - 1)), robot, arm,
                       tabletop_cameras(meta["table_height"], rng), poses),
        "task": {
            "task_cls": TASK_CLS[task],
            "task_type": task,
            "robot_base_pose": [rounded(v) for v in meta["robot_base_pose"]],
            "pickup_obj_name": target.uid,
            "pickup_obj_start_pose": poses[target.uid],
            "succ_pos_threshold": 0.01,
            "task_horizon_sec": 20.0,
        },
        "task_relevant_objects": [target.uid],
        "language": {"task_description": f"pick up {phrase}", "referral_expressions": {"pickup_obj_name": phrase}},
    }


def _receptacle_footprint(rec: BuiltinReceptacle, yaw: float) -> tuple[list[float], float, float]:
    """Orientation, footprint radius and centre height of a receptacle standing on a table."""
    hx, hy, hz = rec.half_extents
    return yaw_quat(yaw), (hx if rec.round else math.hypot(hx, hy)), hz


def _fits(obj: BuiltinObject, rec: BuiltinReceptacle) -> bool:
    """Whether ``obj``'s resting footprint fits inside the receptacle's rim."""
    return _resting(obj, 0.0)[1] <= min(rec.inner_half_size)


def _place_layout(receptacles: list[BuiltinReceptacle], objects: list[BuiltinObject], region: dict[str, Any],
                  rng: np.random.Generator, next_to: bool, fixed: list[tuple[float, float, float]],
                  pick_clearance: float) -> dict[str, list[float]] | None:
    """Poses for ``receptacles`` then ``objects`` (the first is the one to pick), or None if they do not fit.

    Footprints stay MIN_GAP apart from each other and from the ``fixed`` discs (x, y, radius),
    and ``pick_clearance`` more around the object to pick.
    ``next_to``: keep a free disc beside the first receptacle for the object, and start the
    object at least :data:`NEXT_TO_START_GAP` from that receptacle.
    """
    items: list[tuple[BuiltinReceptacle | BuiltinObject, list[float], float, float]] = [
        (r, *_receptacle_footprint(r, float(rng.uniform(-math.pi, math.pi)))) for r in receptacles]
    items += [(o, *_resting(o, float(rng.uniform(-math.pi, math.pi)))) for o in objects]
    pick, quat, pick_radius, height = items[len(receptacles)]
    items[len(receptacles)] = (pick, quat, pick_radius + pick_clearance, height)
    for _ in range(_MAX_TRIES // 4):
        placed: list[tuple[float, float, float]] = []
        poses: dict[str, list[float]] = {}
        for k, (item, quat, radius, height) in enumerate(items):
            for _ in range(50):
                x, y = float(rng.uniform(*region["x"])), float(rng.uniform(*region["y"]))
                ok = all(math.hypot(x - px, y - py) >= radius + pr + MIN_GAP for px, py, pr in placed + fixed)
                if ok and next_to and k == len(receptacles):
                    rx, ry, rr = placed[0]
                    ok = math.hypot(x - rx, y - ry) >= rr + radius + NEXT_TO_START_GAP
                if ok:
                    break
            else:
                break
            placed.append((x, y, radius))
            poses[item.uid] = [rounded(x), rounded(y), rounded(region["z"] + height)] + [rounded(q) for q in quat]
            if next_to and k == 0:  # the free spot beside the receptacle, inside the workspace
                for _ in range(50):
                    a = float(rng.uniform(-math.pi, math.pi))
                    d = radius + pick_radius + NEXT_TO_SPOT_MARGIN
                    sx, sy = x + d * math.cos(a), y + d * math.sin(a)
                    if region["x"][0] <= sx <= region["x"][1] and region["y"][0] <= sy <= region["y"][1]:
                        placed.append((sx, sy, pick_radius + NEXT_TO_SPOT_MARGIN))
                        break
                else:
                    break
        if len(poses) == len(items):
            return poses
    return None


def _article(rec: BuiltinReceptacle) -> str:
    return "on" if rec.shape in ("plate", "tray") else "in"


def _place_episode(scene: ProceduralTabletop, house: int, index: int, seed: int, task: str) -> dict[str, Any]:
    """One pick-and-place / next-to / colour episode (see the module docstring)."""
    rng = np.random.default_rng([seed, house, index])
    meta = scene.metadata(house)
    objects = [BUILTIN_OBJECTS[o["asset_id"]] for o in meta["objects"].values() if not o["receptacle"]]
    receptacles = [BUILTIN_RECEPTACLES[o["asset_id"]] for o in meta["objects"].values() if o["receptacle"]]
    if task == "pick_and_place_color":  # the two of one category, told apart by paint only
        pair = [receptacles[k] for k in rng.permutation(2)]
        in_scene, target = pair, pair[0]
        paints = [list(PAINT_COLORS)[k] for k in rng.choice(len(PAINT_COLORS), 2, replace=False)]
    else:
        order = [receptacles[k] for k in rng.permutation(len(receptacles))]
        target = order[0]
        in_scene = order[:1] if task == "pick_and_place_next_to" else order[:2]
    candidates = [o for o in objects if task == "pick_and_place_next_to" or _fits(o, target)]
    pick = candidates[int(rng.integers(len(candidates)))]
    others = [objects[k] for k in rng.permutation(len(objects)) if objects[k] is not pick]
    defaults = {uid: o["default_pose"] for uid, o in meta["objects"].items()}
    # distractors that do not fit stay in the house's default row; room around the object comes first
    for clearance, n in ((c, n) for c in (PICK_CLEARANCE, 0.0) for n in range(len(others), -1, -1)):
        rest = {o.uid: [rounded(v) for v in defaults[o.uid]] for o in others[n:]}
        fixed = [(p[0], p[1], _resting(BUILTIN_OBJECTS[uid], 0.0)[1]) for uid, p in rest.items()]
        poses = _place_layout(in_scene, [pick, *others[:n]], meta["placement_region"], rng,
                              task == "pick_and_place_next_to", fixed, clearance)
        if poses is not None:
            poses.update(rest)
            break
    else:
        raise RuntimeError(f"house {house}: could not lay out {pick.uid} and {[r.uid for r in in_scene]}")
    robot = Franka()
    arm = np.asarray(robot.default_init_qpos["arm"]) + rng.uniform(-0.05, 0.05, 7)
    cameras = tabletop_cameras(meta["table_height"], rng)
    phrase = f"the {pick.color} {pick.category}"
    task_spec: dict[str, Any] = {
        "task_cls": TASK_CLS[task],
        "task_type": task,
        "robot_base_pose": [rounded(v) for v in meta["robot_base_pose"]],
        "pickup_obj_name": pick.uid,
        "pickup_obj_start_pose": poses[pick.uid],
        "place_receptacle_name": target.uid,
        "place_receptacle_start_pose": poses[target.uid],
        "receptacle_supported_weight_frac": 0.5,
        "max_place_receptacle_pos_displacement": 0.15,
        "max_place_receptacle_rot_displacement": rounded(math.radians(60)),
    }
    if task == "pick_and_place_color":
        colors = dict(zip((r.uid for r in pair), paints, strict=True))
        task_spec["object_colors"] = {uid: list(PAINT_COLORS[c]) for uid, c in colors.items()}
        task_spec["other_receptacle_names"] = [pair[1].uid]
        task_spec["other_receptacle_start_poses"] = {pair[1].uid: poses[pair[1].uid]}
        where = f"the {colors[target.uid]} {target.category}"
        instruction = f"put {phrase} {_article(target)} {where}"
    elif task == "pick_and_place_next_to":
        task_spec["min_surface_to_surface_gap"] = 0.0
        task_spec["max_surface_to_surface_gap"] = 0.05
        where = f"the {target.color} {target.category}"
        instruction = f"put {phrase} next to {where}"
    else:
        where = f"the {target.color} {target.category}"
        instruction = f"put {phrase} {_article(target)} {where}"
    task_spec["task_horizon_sec"] = PLACE_HORIZON_SEC
    return {
        **episode_base(house, scene.name, int(rng.integers(2**31 - 1)), robot, arm, cameras, poses),
        "task": task_spec,
        "task_relevant_objects": [pick.uid, *(r.uid for r in in_scene if r is target or task.endswith("color"))],
        "language": {"task_description": instruction,
                     "referral_expressions": {"pickup_obj_name": phrase, "place_receptacle_name": where}},
    }


#: task families whose scenes and episodes another module generates (same signature)
EXTERNAL_GENERATORS = {"open": "molmo_lerobot.content.articulated.generate",
                       "close": "molmo_lerobot.content.articulated.generate"}


def generate_benchmark(task: str, n_houses: int, episodes_per_house: int, seed: int,
                       name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Episodes (JSON-ready EpisodeSpec dicts) and metadata, fully determined by the arguments."""
    if task in EXTERNAL_GENERATORS:
        module = importlib.import_module(EXTERNAL_GENERATORS[task])
        return module.generate_benchmark(task, n_houses, episodes_per_house, seed, name)
    if task not in TASK_CLS:
        raise ValueError(f"generate: unknown task {task!r} (can generate: {', '.join(TASK_CLS)})")
    if n_houses < 1 or episodes_per_house < 1:
        raise ValueError("generate: n_houses and episodes_per_house must be at least 1")
    scene = ProceduralTabletop() if task == "pick" else ProceduralTabletopReceptacles()
    if n_houses > scene.n_houses():
        raise ValueError(f"generate: n_houses {n_houses} exceeds the {scene.n_houses()} procedural houses")
    houses = sorted(int(h) for h in np.random.default_rng([seed, 0x4855]).choice(scene.n_houses(), n_houses,
                                                                                    replace=False))
    make = _episode if task == "pick" else _place_episode
    episodes = [make(scene, h, i, seed, task) for h in houses for i in range(episodes_per_house)]
    extra = {}
    if task != "pick":
        extra["receptacle_category_counts"] = dict(sorted(Counter(
            BUILTIN_RECEPTACLES[e["task"]["place_receptacle_name"]].category for e in episodes).items()))
    description = (f"{task} on the procedural tabletop: {n_houses} houses x {episodes_per_house} episodes, "
                   f"Franka Panda, exocentric + wrist camera (generator v{GENERATOR_VERSION}, seed {seed})")
    return episodes, benchmark_metadata(name, task, description, episodes, houses, episodes_per_house, seed,
                                        BUILTIN_OBJECTS, GENERATOR_VERSION, **extra)


@hookimpl
def molmo_generators() -> list[BenchmarkGenerator]:
    return [BenchmarkGenerator("v1", "the procedural (and articulated) tabletop, Franka Panda, exocentric + wrist "
                               "camera", (*TASK_CLS, *EXTERNAL_GENERATORS), generate_benchmark)]
