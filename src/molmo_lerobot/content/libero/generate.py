"""Deterministic v2 benchmarks in the textured LIBERO rooms (``libero_rooms``, franka_droid, DROID cameras).

``molmo-bench generate v2 --task pick --houses 20 --episodes-per-house 5 --seed 0 --name pick_v2``
writes pick_v2. :data:`TASKS` maps each ``--task`` to its task type, horizon and episode function
(``open`` / ``close``: :mod:`molmo_lerobot.content.libero.generate_articulated`).

``pick``: per episode a house, the object to pick (a graspable one), a collision-free layout of it and
two or three of the house's other objects inside the robot's workspace (the rest stay where the house
puts them, and the layout keeps clear of them too), the robot's start pose
(:data:`~molmo_lerobot.content.libero.episode_fields.READY_ARM`, the gripper 0.27 m above the table pointing
down, small joint jitter). The layout is then settled: the
house (without the robot) is simulated for :data:`SETTLE_S` and the resting poses are what the episode
records; a layout in which anything moved more than :data:`MAX_SETTLE_SHIFT` is drawn again.

``pick_and_place`` / ``next_to`` / ``color`` (task types ``pick_and_place``, ``pick_and_place_next_to``,
``pick_and_place_color``): the receptacle is one of the house's three (two of one category in different
colours, one of another); the object to pick is a graspable one whose footprint passes the receptacle's
rim (:attr:`~molmo_lerobot.content.libero.objects.LiberoObject.opening_radius`; any for ``next_to``). Laid out
in the workspace and settled as for ``pick``: the receptacle, for ``pick_and_place`` a second receptacle
where it fits, for ``color`` the other receptacle of its pair (the two differ only in colour), the
object (room for the open hand around it; for ``next_to`` at least :data:`NEXT_TO_START_GAP` from the
receptacle, with a free spot kept beside the receptacle) and up to two other graspable objects.

Language comes from the object metadata: the shortest referring expression (name, colour + name, colour
+ material + name) that no other object of the house fits ("put the ketchup bottle in the red bowl").
``cameras: []``: the DROID camera system (wrist + shoulder camera) builds them. Same arguments, same
JSON (on the same MuJoCo build).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.generators import BenchmarkGenerator
from molmo_lerobot.benchmark.output import benchmark_metadata, rounded
from molmo_lerobot.content.libero.episode_fields import CAMERA_SYSTEM, episode_fields, start_arm
from molmo_lerobot.content.libero.generate_articulated import TASKS as ARTICULATED_TASKS
from molmo_lerobot.content.libero.generate_articulated import generate_benchmark as generate_articulated
from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS
from molmo_lerobot.content.libero.rooms import REGION_X, REGION_Y, LiberoRooms, resting_radius
from molmo_lerobot.poses import yaw_quat
from molmo_lerobot.sim.env import PHYSICS_OPTIONS

GENERATOR_VERSION = 2
#: free space between footprints in the workspace, and more around the object to pick (the open hand)
MIN_GAP = 0.04
PICK_CLEARANCE = 0.07
SETTLE_S = 0.6
MAX_SETTLE_SHIFT = 0.01
SIM_DT = 0.002
_MAX_TRIES = 50
#: the least free space around the object to pick in place episodes (when :data:`PICK_CLEARANCE` does not fit)
PLACE_MIN_CLEARANCE = 0.03
#: layouts drawn per receptacle choice and number of neighbours in place episodes
_PLACE_TRIES = 10
#: next-to episodes start the object's footprint at least this far from the receptacle's, and keep a
#: free disc of the object's footprint + :data:`NEXT_TO_SPOT_MARGIN` beside the receptacle
NEXT_TO_START_GAP = 0.12
NEXT_TO_SPOT_MARGIN = 0.03
#: receptacle categories an object is put on (the others: in)
_ON = ("plate", "tray")


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
        out[name] = [rounded(v) for v in data.xpos[b]] + [rounded(v) for v in data.xquat[b]]
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
        poses[uid] = [x, y, z + obj.half_extents[2] + 0.002, *yaw_quat(float(rng.uniform(-math.pi, math.pi)))]
    return poses


def _pick_episode(scene: LiberoRooms, house: int, index: int, seed: int, task: str) -> dict[str, Any]:
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
    arm = start_arm(rng)
    phrase = objects[target]["referring_expression"]
    return {
        **episode_fields(scene.name, house, rng, arm, settled),
        "task": {
            "task_cls": TASKS["pick"].task_cls,
            "task_type": "pick",
            "robot_base_pose": [rounded(v) for v in meta["robot_base_pose"]],
            "pickup_obj_name": target,
            "pickup_obj_start_pose": settled[target],
            "succ_pos_threshold": 0.01,
            "task_horizon_sec": TASKS["pick"].horizon_sec,
        },
        "task_relevant_objects": [target],
        "language": {"task_description": f"pick up {phrase}", "referral_expressions": {"pickup_obj_name": phrase}},
    }


def _place_layout(items: list[tuple[str, float]], z: float, defaults: dict[str, list[float]], next_to: bool,
                  rng: np.random.Generator) -> dict[str, list[float]] | None:
    """Poses for ``items`` (UID, extra free radius around it: the receptacles, then the object to pick, then
    its neighbours) inside the workspace, footprints apart (also from the objects left at their ``defaults``
    poses), or None. ``next_to``: the object starts :data:`NEXT_TO_START_GAP` from the first
    receptacle, and a disc beside that receptacle, inside the workspace, is kept free for it."""
    uids = [uid for uid, _ in items]
    placed = [(pose[0], pose[1], resting_radius(LIBERO_OBJECTS[uid])) for uid, pose in defaults.items()
              if uid not in uids]
    pick = next(k for k, (uid, _) in enumerate(items) if not LIBERO_OBJECTS[uid].receptacle)
    pick_radius = resting_radius(LIBERO_OBJECTS[uids[pick]])
    poses: dict[str, list[float]] = {}
    first = (0.0, 0.0, 0.0)  # the first receptacle's disc
    for k, (uid, extra) in enumerate(items):
        obj = LIBERO_OBJECTS[uid]
        r = resting_radius(obj) + extra
        for _ in range(100):
            x, y = float(rng.uniform(*REGION_X)), float(rng.uniform(*REGION_Y))
            ok = all(math.hypot(x - px, y - py) >= r + pr + MIN_GAP for px, py, pr in placed)
            if ok and next_to and k == pick:
                ok = math.hypot(x - first[0], y - first[1]) >= first[2] + pick_radius + NEXT_TO_START_GAP
            if ok:
                break
        else:
            return None
        placed.append((x, y, r))
        poses[uid] = [x, y, z + obj.half_extents[2] + 0.002, *yaw_quat(float(rng.uniform(-math.pi, math.pi)))]
        if k == 0:
            first = (x, y, r)
        if next_to and k == 0:  # the free spot beside the first receptacle
            for _ in range(50):
                a = float(rng.uniform(-math.pi, math.pi))
                d = r + pick_radius + NEXT_TO_SPOT_MARGIN
                sx, sy = x + d * math.cos(a), y + d * math.sin(a)
                if REGION_X[0] <= sx <= REGION_X[1] and REGION_Y[0] <= sy <= REGION_Y[1]:
                    placed.append((sx, sy, pick_radius + NEXT_TO_SPOT_MARGIN))
                    break
            else:
                return None
    return poses


def _receptacle_options(task: str, receptacles: list[str], rng: np.random.Generator) -> list[list[str]]:
    """The receptacles to lay out, the one to place at first, in the order they are tried: ``color`` the
    house's pair (either one the target), ``next_to`` each receptacle alone, ``pick_and_place`` each with
    a second receptacle, then each alone."""
    if task == "color":
        return [[receptacles[int(k)], receptacles[1 - int(k)]] for k in rng.permutation(2)]
    order = [receptacles[int(k)] for k in rng.permutation(len(receptacles))]
    alone = [[u] for u in order]
    if task == "next_to":
        return alone
    return [[u, next(v for v in order if v != u)] for u in order] + alone


def _fitting(task: str, target: str, graspable: list[str]) -> list[str]:
    """The graspable objects that may be put at ``target`` (in/on it: those passing its rim)."""
    rim = LIBERO_OBJECTS[target].opening_radius
    return [u for u in graspable if task == "next_to" or resting_radius(LIBERO_OBJECTS[u]) <= rim]


def _house_fits(task: str, meta: dict[str, Any]) -> bool:
    """Whether the house has a receptacle the task may use with a graspable object that fits it."""
    objects = meta["objects"]
    receptacles = [u for u, o in objects.items() if o["receptacle"]]
    graspable = [u for u, o in objects.items() if o["graspable"]]
    return any(_fitting(task, u, graspable) for u in (receptacles[:2] if task == "color" else receptacles))


def _place_layout_settled(house: int, task: str, in_scene: list[str], graspable: list[str],
                          defaults: dict[str, list[float]], z: float, rng: np.random.Generator
                          ) -> tuple[list[str], str, dict[str, list[float]]] | None:
    """(receptacles, object to pick, settled poses of the house) of a layout with ``in_scene`` that settles
    (up to two other graspable objects, fewer when they do not fit, and at last less room around the object
    to pick: :data:`PLACE_MIN_CLEARANCE`), or None."""
    fits = _fitting(task, in_scene[0], graspable)
    if not fits:
        return None
    pick = fits[int(rng.integers(len(fits)))]
    others = [graspable[int(k)] for k in rng.permutation(len(graspable)) if graspable[int(k)] != pick]
    for clearance, n in ((PICK_CLEARANCE, 2), (PICK_CLEARANCE, 1), (PICK_CLEARANCE, 0), (PLACE_MIN_CLEARANCE, 0)):
        items = [(u, 0.0) for u in in_scene] + [(pick, clearance)] + [(u, 0.0) for u in others[:n]]
        for _ in range(_PLACE_TRIES):
            near = _place_layout(items, z, defaults, task == "next_to", rng)
            if near is None:
                continue
            settled, shift = settle(house, {**defaults, **near})
            if shift <= MAX_SETTLE_SHIFT:
                return in_scene, pick, settled
    return None


def _place_episode(scene: LiberoRooms, house: int, index: int, seed: int, task: str) -> dict[str, Any]:
    """One ``pick_and_place`` / ``next_to`` / ``color`` episode (see the module docstring)."""
    kind = TASKS[task]
    rng = np.random.default_rng([seed, house, index, 0x2, kind.salt])
    meta = scene.metadata(house)
    objects = meta["objects"]
    receptacles = [u for u, o in objects.items() if o["receptacle"]]  # the pair of one category, then one
    graspable = [u for u, o in objects.items() if o["graspable"]]
    defaults = {u: o["default_pose"] for u, o in objects.items()}
    found = None
    for in_scene in _receptacle_options(task, receptacles, rng):
        found = _place_layout_settled(house, task, in_scene, graspable, defaults, meta["table_height"], rng)
        if found is not None:
            break
    if found is None:
        raise RuntimeError(f"libero_rooms house {house}: no layout of a receptacle, an object that fits it and "
                           f"the neighbours settles within {MAX_SETTLE_SHIFT} m")
    in_scene, pick, settled = found
    target = in_scene[0]
    arm = start_arm(rng)
    phrase = objects[pick]["referring_expression"]
    where = objects[target]["referring_expression"]
    spec: dict[str, Any] = {
        "task_cls": kind.task_cls,
        "task_type": kind.task_type,
        "robot_base_pose": [rounded(v) for v in meta["robot_base_pose"]],
        "pickup_obj_name": pick,
        "pickup_obj_start_pose": settled[pick],
        "place_receptacle_name": target,
        "place_receptacle_start_pose": settled[target],
        "receptacle_supported_weight_frac": 0.5,
        "max_place_receptacle_pos_displacement": 0.15,
        "max_place_receptacle_rot_displacement": rounded(math.radians(60)),
    }
    if task == "next_to":
        spec["min_surface_to_surface_gap"] = 0.0
        spec["max_surface_to_surface_gap"] = 0.05
        instruction = f"put {phrase} next to {where}"
    else:
        instruction = f"put {phrase} {'on' if objects[target]['category'] in _ON else 'in'} {where}"
    if task == "color":
        spec["other_receptacle_names"] = in_scene[1:]
        spec["other_receptacle_start_poses"] = {u: settled[u] for u in in_scene[1:]}
    spec["task_horizon_sec"] = kind.horizon_sec
    return {
        **episode_fields(scene.name, house, rng, arm, settled),
        "task": spec,
        "task_relevant_objects": [pick, *in_scene] if task == "color" else [pick, target],
        "language": {"task_description": instruction,
                     "referral_expressions": {"pickup_obj_name": phrase, "place_receptacle_name": where}},
    }


@dataclass(frozen=True)
class TaskKind:
    """What ``--task`` generates: the task type, its class path, the horizon written into each episode,
    the episode function ``(scene, house, index, seed, task) -> episode``, its random-stream salt, and
    whether a house can hold the task (``(task, house metadata) -> bool``; None: every house can)."""

    task_type: str
    task_cls: str
    horizon_sec: float
    episode: Callable[[LiberoRooms, int, int, int, str], dict[str, Any]]
    salt: int = 0
    house_fits: Callable[[str, dict[str, Any]], bool] | None = None


_P = "molmo_lerobot.tasks.pick_and_place."
#: ``--task`` -> what it generates
TASKS: dict[str, TaskKind] = {
    "pick": TaskKind("pick", "molmo_lerobot.tasks.pick.PickTask", 20.0, _pick_episode),
    "pick_and_place": TaskKind("pick_and_place", _P + "PickAndPlaceTask", 40.0, _place_episode, 1, _house_fits),
    "next_to": TaskKind("pick_and_place_next_to", _P + "PickAndPlaceNextToTask", 40.0, _place_episode, 2, _house_fits),
    "color": TaskKind("pick_and_place_color", _P + "PickAndPlaceColorTask", 40.0, _place_episode, 3, _house_fits),
}


def generate_benchmark(task: str, n_houses: int, episodes_per_house: int, seed: int,
                       name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Episodes (JSON-ready EpisodeSpec dicts) and metadata, fully determined by the arguments
    (``open`` / ``close``: :mod:`molmo_lerobot.content.libero.generate_articulated`'s)."""
    if task in ARTICULATED_TASKS:
        return generate_articulated(task, n_houses, episodes_per_house, seed, name)
    if task not in TASKS:
        raise ValueError(f"generate_v2: unknown task {task!r} (can generate: {', '.join(TASKS)})")
    if n_houses < 1 or episodes_per_house < 1:
        raise ValueError("generate_v2: n_houses and episodes_per_house must be at least 1")
    scene = LiberoRooms()
    kind = TASKS[task]
    draw = np.random.default_rng([seed, 0x4855, 0x2])
    if kind.house_fits is None:
        houses = sorted(int(h) for h in draw.choice(scene.n_houses(), n_houses, replace=False))
    else:  # the first houses of a random order that can hold the task
        fitting = (int(h) for h in draw.permutation(scene.n_houses()) if kind.house_fits(task, scene.metadata(int(h))))
        houses = sorted(h for _, h in zip(range(n_houses), fitting, strict=False))
    if len(houses) < n_houses:
        raise ValueError(f"generate_v2: only {len(houses)} houses can hold {task!r}, {n_houses} asked for")
    make = kind.episode
    episodes = [make(scene, h, i, seed, task) for h in houses for i in range(episodes_per_house)]
    styles = {h: scene.metadata(h)["style"] for h in houses}
    extra = {}
    if task != "pick":
        extra["receptacle_category_counts"] = dict(sorted(Counter(
            LIBERO_OBJECTS[e["task"]["place_receptacle_name"]].category for e in episodes).items()))
    description = (f"{task} in textured LIBERO rooms: {n_houses} houses x {episodes_per_house} episodes, "
                   f"franka_droid, DROID cameras (generator v{GENERATOR_VERSION}, seed {seed})")
    meta = benchmark_metadata(name, task, description, episodes, houses, episodes_per_house, seed, LIBERO_OBJECTS,
                              GENERATOR_VERSION, **extra, room_style_counts={s: list(styles.values()).count(s)
                                                                             for s in sorted(set(styles.values()))})
    meta["camera_system_class"] = CAMERA_SYSTEM
    return episodes, meta


@hookimpl
def molmo_generators() -> list[BenchmarkGenerator]:
    return [BenchmarkGenerator("v2", "textured LIBERO rooms (and LIBERO cabinets), franka_droid, DROID cameras",
                               (*TASKS, *ARTICULATED_TASKS), generate_benchmark)]
