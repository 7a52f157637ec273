"""Deterministic benchmark generation on the procedural tabletop (``molmo-bench generate``).

``generate_benchmark`` draws houses and, per episode, a collision-free layout of every
house object inside the robot's workspace, the object to pick, the robot's start pose
(small joint jitter) and the exocentric camera (small jitter). The same arguments always
give the same episodes (byte-identical JSON).
"""

from __future__ import annotations

import importlib
import json
import math
import os
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, BuiltinObject
from molmo_lerobot.cameras.base import look_rotation, mat_to_quat
from molmo_lerobot.robots.franka import Franka
from molmo_lerobot.sim.tabletop import ProceduralTabletop

GENERATOR_VERSION = 1
TASK_CLS = {"pick": "molmo_lerobot.tasks.pick.PickTask"}
IMG_RESOLUTION = (224, 224)
#: free space kept between the bounding circles of neighbouring objects (room for fingers)
MIN_GAP = 0.05
_MAX_TRIES = 200


def _r(x: float) -> float:
    """Round for stable, readable JSON."""
    return round(float(x), 5)


def _yaw_quat(yaw: float) -> list[float]:
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


def _quat_mul(a: list[float], b: list[float]) -> list[float]:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return [w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2]


def _resting(obj: BuiltinObject, yaw: float) -> tuple[list[float], float, float]:
    """Orientation of ``obj`` resting on a table, its footprint radius and its centre height."""
    hx, hy, hz = obj.half_extents
    if obj.shape == "capsule":  # lies on its side: local z along world x, then yaw
        lie = [math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0]
        return _quat_mul(_yaw_quat(yaw), lie), math.hypot(hz, hx), hx
    return _yaw_quat(yaw), math.hypot(hx, hy), hz


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
            poses[obj.uid] = [_r(x), _r(y), _r(region["z"] + height)] + [_r(q) for q in quat]
        if len(poses) == len(objects):
            return poses
    raise RuntimeError(f"could not place {len(objects)} objects in {region} after {_MAX_TRIES} tries")


def _cameras(table_height: float, rng: np.random.Generator) -> list[dict[str, Any]]:
    """An exocentric camera beside the table (jittered) and a wrist camera on the hand."""
    eye = np.array([1.3, -0.6, table_height + 0.7]) + rng.uniform(-0.03, 0.03, 3)
    target = np.array([0.38, 0.0, table_height + 0.12])
    forward = target - eye
    exo = {"name": "exterior", "type": "exocentric", "pos": [_r(v) for v in eye], "up": [0.0, 0.0, 1.0],
           "forward": [_r(v) for v in forward / np.linalg.norm(forward)], "fov": 55.0, "record_depth": False}
    # wrist camera in link 7's frame: beside the hand, across the finger axis, looking past the fingertips
    side = np.array([math.sqrt(0.5), -math.sqrt(0.5), 0.0])
    offset = 0.075 * side + np.array([0.0, 0.0, 0.12])
    lookat = np.array([0.0, 0.0, 0.32])
    quat = mat_to_quat(look_rotation(lookat - offset, side))
    wrist = {"name": "wrist", "type": "robot_mounted", "reference_body_names": ["panda0_link7"],
             "camera_offset": [_r(v) for v in offset], "lookat_offset": [_r(v) for v in lookat],
             "camera_quaternion": [_r(q) for q in quat], "fov": 75.0, "record_depth": False}
    return [exo, wrist]


def _episode(scene: ProceduralTabletop, house: int, index: int, seed: int, task: str) -> dict[str, Any]:
    rng = np.random.default_rng([seed, house, index])
    meta = scene.metadata(house)
    objects = [BUILTIN_OBJECTS[o["asset_id"]] for o in meta["objects"].values()]
    poses = _layout(objects, meta["placement_region"], rng)
    target = objects[int(rng.integers(len(objects)))]
    robot = Franka()
    arm = np.asarray(robot.default_init_qpos["arm"]) + rng.uniform(-0.05, 0.05, 7)
    phrase = f"the {target.color} {target.category}"
    return {
        "house_index": house,
        "scene_dataset": scene.name,
        "data_split": "val",
        "seed": int(rng.integers(2**31 - 1)),
        "robot": {"robot_name": robot.name,
                  "init_qpos": {"arm": [_r(q) for q in arm], "gripper": list(robot.default_init_qpos["gripper"])}},
        "img_resolution": list(IMG_RESOLUTION),
        "cameras": _cameras(meta["table_height"], rng),
        "scene_modifications": {"added_objects": {}, "object_poses": poses, "removed_objects": []},
        "task": {
            "task_cls": TASK_CLS[task],
            "task_type": task,
            "robot_base_pose": [_r(v) for v in meta["robot_base_pose"]],
            "pickup_obj_name": target.uid,
            "pickup_obj_start_pose": poses[target.uid],
            "succ_pos_threshold": 0.01,
            "task_horizon_sec": 20.0,
        },
        "task_relevant_objects": [target.uid],
        "language": {"task_description": f"pick up {phrase}", "referral_expressions": {"pickup_obj_name": phrase}},
    }


#: task families whose scenes and episodes another module generates (same signature)
EXTERNAL_GENERATORS = {"open": "molmo_lerobot.benchmark.generate_articulated",
                       "close": "molmo_lerobot.benchmark.generate_articulated"}


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
    scene = ProceduralTabletop()
    if n_houses > scene.n_houses():
        raise ValueError(f"generate: n_houses {n_houses} exceeds the {scene.n_houses()} procedural houses")
    houses = sorted(int(h) for h in np.random.default_rng([seed, 0x4855]).choice(scene.n_houses(), n_houses,
                                                                                    replace=False))
    episodes = [_episode(scene, h, i, seed, task) for h in houses for i in range(episodes_per_house)]
    categories = Counter(BUILTIN_OBJECTS[e["task"]["pickup_obj_name"]].category for e in episodes)
    metadata = {
        "name": name,
        "description": f"{task} on the procedural tabletop: {n_houses} houses x {episodes_per_house} episodes, "
                       f"Franka Panda, exocentric + wrist camera (generator v{GENERATOR_VERSION}, seed {seed})",
        "num_episodes": len(episodes),
        "num_houses": n_houses,
        "task_cls_counts": dict(Counter(e["task"]["task_cls"] for e in episodes)),
        "object_category_counts": dict(sorted(categories.items())),
        "robot_counts": dict(Counter(e["robot"]["robot_name"] for e in episodes)),
        "house_counts": {str(h): episodes_per_house for h in houses},
        "camera_system_class": "standard",
        "generator": {"task": task, "n_houses": n_houses, "episodes_per_house": episodes_per_house, "seed": seed,
                      "version": GENERATOR_VERSION},
    }
    return episodes, metadata


def _write_atomic(path: Path, obj: Any) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; a benchmark is meant to be shared
        with os.fdopen(fd, "w") as f:
            json.dump(obj, f, indent=1)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_benchmark(out_dir: str | Path, episodes: list[dict[str, Any]], metadata: dict[str, Any]) -> Path:
    """Write ``benchmark.json`` and ``benchmark_metadata.json`` (each atomically) into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _write_atomic(out / "benchmark_metadata.json", metadata)
    _write_atomic(out / "benchmark.json", episodes)
    return out
