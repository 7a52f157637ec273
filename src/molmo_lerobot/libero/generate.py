"""Deterministic v2 benchmarks in the textured LIBERO rooms (``libero_rooms``, franka_droid, DROID cameras).

``python -m molmo_lerobot.libero.generate --task pick --houses 20 --episodes-per-house 5 --seed 0
--name pick_v2 --out benchmarks/pick_v2`` writes the same two files as ``molmo-bench generate``
(:func:`~molmo_lerobot.benchmark.generate.write_benchmark`). Per episode: a house, the object to
pick (a graspable one), a collision-free layout of it and two or three of the house's other objects
inside the robot's workspace (the rest stay where the house puts them, and the layout keeps clear
of them too), the robot's start pose
(:data:`READY_ARM`, the gripper 0.27 m above the table pointing down, small joint jitter). The layout
is then settled: the house (without the robot) is simulated for :data:`SETTLE_S` and the resting
poses are what the episode records; a layout in which anything moved more than
:data:`MAX_SETTLE_SHIFT` is drawn again. Language comes from the object metadata: the shortest
referring expression (name, colour + name, colour + material + name) that no other object of the
house fits. ``cameras: []``: the DROID camera system (wrist + shoulder camera) builds them.
Same arguments, same JSON (on the same MuJoCo build).
"""

from __future__ import annotations

import argparse
import math
from functools import cache
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot.benchmark.generate import _r, _yaw_quat, benchmark_metadata, write_benchmark
from molmo_lerobot.libero.objects import LIBERO_OBJECTS
from molmo_lerobot.libero.rooms import REGION_X, REGION_Y, LiberoRooms, resting_radius
from molmo_lerobot.sim.env import PHYSICS_OPTIONS

GENERATOR_VERSION = 2
TASK_CLS = {"pick": "molmo_lerobot.tasks.pick.PickTask"}
HORIZON_SEC = {"pick": 20.0}
IMG_RESOLUTION = (224, 224)
ROBOT = "franka_droid"
CAMERA_SYSTEM = "FrankaDroidCameraSystem"
#: TCP 0.45 m ahead of the base, 1.02 m above the floor, pointing down (IK on franka_droid on its pedestal)
READY_ARM = (0.0, -0.345, 0.0, -2.044, 0.0, 1.699, 0.0)
#: free space between footprints in the workspace, and more around the object to pick (the open hand)
MIN_GAP = 0.04
PICK_CLEARANCE = 0.07
SETTLE_S = 0.6
MAX_SETTLE_SHIFT = 0.01
SIM_DT = 0.002
_MAX_TRIES = 50


@cache
def _settle_model(house: int) -> mujoco.MjModel:
    world = LiberoRooms().build(house)
    world.option.timestep = SIM_DT
    for option, value in PHYSICS_OPTIONS.items():
        setattr(world.option, option, value)
    return world.compile()


def settle(house: int, poses: dict[str, list[float]]) -> tuple[dict[str, list[float]], float]:
    """``poses`` after :data:`SETTLE_S` of physics in the house (no robot), and the largest shift (m)."""
    model = _settle_model(house)
    data = mujoco.MjData(model)
    for name, pose in poses.items():
        adr = model.jnt_qposadr[model.body_jntadr[model.body(name).id]]
        data.qpos[adr:adr + 7] = pose
    mujoco.mj_forward(model, data)
    mujoco.mj_step(model, data, nstep=int(SETTLE_S / SIM_DT))
    out, shift = {}, 0.0
    for name, pose in poses.items():
        b = model.body(name).id
        out[name] = [_r(v) for v in data.xpos[b]] + [_r(v) for v in data.xquat[b]]
        shift = max(shift, float(np.linalg.norm(data.xpos[b] - pose[:3])))
    return out, shift


def _layout(house: int, target: str, others: list[str], z: float, defaults: dict[str, list[float]],
            rng: np.random.Generator) -> dict[str, list[float]] | None:
    """Poses for ``target`` and ``others`` inside the workspace, footprints apart (also from the objects
    left at their ``defaults`` poses), or None."""
    placed = [(pose[0], pose[1], resting_radius(LIBERO_OBJECTS[uid])) for uid, pose in defaults.items()
              if uid not in (target, *others)]
    poses = {}
    for k, uid in enumerate([target, *others]):
        obj = LIBERO_OBJECTS[uid]
        r = resting_radius(obj) + (PICK_CLEARANCE if k == 0 else 0.0)
        for _ in range(100):
            x, y = float(rng.uniform(*REGION_X)), float(rng.uniform(*REGION_Y))
            if all(math.hypot(x - px, y - py) >= r + pr + MIN_GAP for px, py, pr in placed):
                break
        else:
            return None
        placed.append((x, y, r))
        poses[uid] = [x, y, z + obj.half_extents[2] + 0.002, *_yaw_quat(float(rng.uniform(-math.pi, math.pi)))]
    return poses


def _pick_episode(scene: LiberoRooms, house: int, index: int, seed: int) -> dict[str, Any]:
    rng = np.random.default_rng([seed, house, index, 0x2])
    meta = scene.metadata(house)
    objects = meta["objects"]
    graspable = [u for u, o in objects.items() if o["graspable"]]
    target = graspable[int(rng.integers(len(graspable)))]
    small = [u for u, o in objects.items() if u != target and resting_radius(LIBERO_OBJECTS[u]) < 0.1]
    defaults = {u: o["default_pose"] for u, o in objects.items()}
    for _ in range(_MAX_TRIES):
        n = int(rng.integers(2, 4))
        others = [small[int(k)] for k in rng.choice(len(small), n, replace=False)]
        near = _layout(house, target, others, meta["table_height"], defaults, rng)
        if near is None:
            continue
        settled, shift = settle(house, {**defaults, **near})
        if shift <= MAX_SETTLE_SHIFT:
            break
    else:
        raise RuntimeError(f"libero_rooms house {house}: no layout for {target!r} settles within {MAX_SETTLE_SHIFT} m")
    arm = np.asarray(READY_ARM) + rng.uniform(-0.05, 0.05, 7)
    phrase = objects[target]["referring_expression"]
    return {
        "house_index": house,
        "scene_dataset": scene.name,
        "data_split": "val",
        "seed": int(rng.integers(2**31 - 1)),
        "robot": {"robot_name": ROBOT, "init_qpos": {"arm": [_r(q) for q in arm], "gripper": [0.0]}},
        "img_resolution": list(IMG_RESOLUTION),
        "cameras": [],
        "scene_modifications": {"added_objects": {}, "object_poses": settled, "removed_objects": []},
        "task": {
            "task_cls": TASK_CLS["pick"],
            "task_type": "pick",
            "robot_base_pose": [_r(v) for v in meta["robot_base_pose"]],
            "pickup_obj_name": target,
            "pickup_obj_start_pose": settled[target],
            "succ_pos_threshold": 0.01,
            "task_horizon_sec": HORIZON_SEC["pick"],
        },
        "task_relevant_objects": [target],
        "language": {"task_description": f"pick up {phrase}", "referral_expressions": {"pickup_obj_name": phrase}},
    }


def generate_benchmark(task: str, n_houses: int, episodes_per_house: int, seed: int,
                       name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Episodes (JSON-ready EpisodeSpec dicts) and metadata, fully determined by the arguments."""
    if task not in TASK_CLS:
        raise ValueError(f"generate_v2: unknown task {task!r} (can generate: {', '.join(TASK_CLS)})")
    if n_houses < 1 or episodes_per_house < 1:
        raise ValueError("generate_v2: n_houses and episodes_per_house must be at least 1")
    scene = LiberoRooms()
    houses = sorted(int(h) for h in np.random.default_rng([seed, 0x4855, 0x2]).choice(scene.n_houses(), n_houses,
                                                                                        replace=False))
    episodes = [_pick_episode(scene, h, i, seed) for h in houses for i in range(episodes_per_house)]
    styles = {h: scene.metadata(h)["style"] for h in houses}
    description = (f"{task} in textured LIBERO rooms: {n_houses} houses x {episodes_per_house} episodes, "
                   f"franka_droid, DROID cameras (generator v{GENERATOR_VERSION}, seed {seed})")
    meta = benchmark_metadata(name, task, description, episodes, houses, episodes_per_house, seed, LIBERO_OBJECTS,
                              GENERATOR_VERSION, room_style_counts={s: list(styles.values()).count(s)
                                                                    for s in sorted(set(styles.values()))})
    meta["camera_system_class"] = CAMERA_SYSTEM
    return episodes, meta


def main(argv: list[str] | None = None) -> None:
    from molmo_lerobot.libero.generate_articulated import TASKS as ARTICULATED_TASKS
    from molmo_lerobot.libero.generate_articulated import generate_benchmark as generate_articulated

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", required=True, choices=sorted({*TASK_CLS, *ARTICULATED_TASKS}))
    parser.add_argument("--houses", type=int, required=True)
    parser.add_argument("--episodes-per-house", type=int, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--name", required=True)
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    generate = generate_articulated if args.task in ARTICULATED_TASKS else generate_benchmark
    episodes, meta = generate(args.task, args.houses, args.episodes_per_house, args.seed, args.name)
    print(write_benchmark(args.out, episodes, meta))


if __name__ == "__main__":
    main()
