"""Deterministic open/close benchmarks on the articulated tabletop (``molmo-bench generate --task open``).

Per episode: a house, one articulated joint of one of its objects (handle within reach;
sliding joints only for close, see :data:`CLOSE_KINDS`), the joint's initial state in
``task.joint_start_position`` (closed for open tasks; 95–100 % open for close tasks, so that
a close episode never starts near solved), the robot's start pose (a level hand ahead of
the robot, small joint jitter) and the exocentric camera (small jitter). Episodes use
MolmoSpaces' ``OpeningTask`` class with ``task_type`` open/close. Same arguments, same JSON.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot.benchmark.output import benchmark_metadata, rounded
from molmo_lerobot.content.articulated.objects import ARTICULATED_OBJECTS
from molmo_lerobot.content.articulated.scene import ArticulatedTabletop
from molmo_lerobot.content.tabletop.generate import episode_base, tabletop_cameras
from molmo_lerobot.robots.franka import Franka

GENERATOR_VERSION = 1
TASK_CLS = "molmo_spaces.tasks.opening_tasks.OpeningTask"
THRESHOLD = 0.2
HORIZON_SEC = 15.0
#: handles farther than this from the robot base (horizontally) are not chosen
MAX_REACH = 0.8
#: joint kinds close episodes target. A hinged door 85 % open shows its handle side away from a
#: robot in front of the object (closing it takes a push from outside the door): not yet scripted.
CLOSE_KINDS = ("slide",)
#: opening fraction range of the joint at the start of a close episode
CLOSE_START = (0.95, 1.0)
#: start pose: hand level, pointing forward 0.25 m ahead and 1.1 m above the base, above the objects
READY_ARM = (-0.9, -0.592, 0.0, -1.148, 0.0, 2.127, 0.785)


@cache
def _handles(house: int) -> dict[tuple[str, str], tuple[float, float, float]]:
    """World position of every closed handle in ``house`` (the house compiled once, kinematics only)."""
    scene = ArticulatedTabletop()
    model = scene.build(house).compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    out: dict[tuple[str, str], tuple[float, float, float]] = {}
    for uid, obj in scene.metadata(house)["objects"].items():
        for joint, j in obj.get("joints", {}).items():
            b = model.body(j["body"]).id
            local = np.asarray(ARTICULATED_OBJECTS[uid].joint(joint).handle_pos)
            x, y, z = (float(v) for v in data.xpos[b] + data.xmat[b].reshape(3, 3) @ local)
            out[(uid, joint)] = (x, y, z)
    return out


def _exterior(table_height: float, rng: np.random.Generator) -> dict[str, Any]:
    """An exocentric camera at the robot's right, behind it, looking over the objects' fronts."""
    eye = np.array([-0.35, -0.85, table_height + 0.85]) + rng.uniform(-0.03, 0.03, 3)
    target = np.array([0.5, 0.0, table_height + 0.15])
    forward = target - eye
    return {"name": "exterior", "type": "exocentric", "pos": [rounded(v) for v in eye], "up": [0.0, 0.0, 1.0],
            "forward": [rounded(v) for v in forward / np.linalg.norm(forward)], "fov": 60.0, "record_depth": False}


def _candidates(house: int, meta: dict[str, Any], task: str) -> list[tuple[str, str]]:
    """(object, joint) pairs of ``house`` an episode of ``task`` may target."""
    base = np.array(meta["robot_base_pose"][:2])
    out = []
    for (uid, joint), pos in sorted(_handles(house).items()):
        if np.linalg.norm(np.array(pos[:2]) - base) > MAX_REACH:
            continue
        if task == "close" and ARTICULATED_OBJECTS[uid].joint(joint).kind not in CLOSE_KINDS:
            continue
        out.append((uid, joint))
    return out


def _phrase(uid: str, joint: str, meta: dict[str, Any]) -> str:
    obj = ARTICULATED_OBJECTS[uid]
    if len(obj.joints) > 1:
        return f"the {obj.joint(joint).label} of the {obj.description}"
    same = [u for u, o in meta["objects"].items() if o.get("category") == obj.category]
    return f"the {obj.description}" if len(same) <= 1 else f"the {obj.description} ({uid})"


def _episode(scene: ArticulatedTabletop, house: int, index: int, seed: int, task: str) -> dict[str, Any]:
    rng = np.random.default_rng([seed, house, index, 0x0C])
    meta = scene.metadata(house)
    candidates = _candidates(house, meta, task)
    uid, joint = candidates[int(rng.integers(len(candidates)))]
    info = ARTICULATED_OBJECTS[uid]
    j = info.joint(joint)
    start = 0.0 if task == "open" else j.open_q * float(rng.uniform(*CLOSE_START))
    robot = Franka()
    arm = np.asarray(READY_ARM) + rng.uniform(-0.05, 0.05, 7)
    wrist = [c for c in tabletop_cameras(meta["table_height"], rng) if c["name"] == "wrist"]
    phrase = _phrase(uid, joint, meta)
    obj_meta = meta["objects"][uid]
    # arguments are evaluated in order: the episode seed is drawn before the exterior camera
    return {
        **episode_base(house, scene.name, int(rng.integers(2**31 - 1)), robot, arm,
                       [_exterior(meta["table_height"], rng), *wrist], {}),
        "task": {
            "task_cls": TASK_CLS,
            "task_type": task,
            "robot_base_pose": [rounded(v) for v in meta["robot_base_pose"]],
            "pickup_obj_name": uid,
            "pickup_obj_start_pose": [rounded(v) for v in obj_meta["default_pose"]],
            "articulation_object_name": uid,
            "joint_name": obj_meta["joints"][joint]["joint"],
            "joint_index": [jj.name for jj in info.joints].index(joint),
            "joint_start_position": rounded(start),
            "task_success_threshold": THRESHOLD,
            "task_horizon_sec": HORIZON_SEC,
        },
        "task_relevant_objects": [uid],
        "language": {"task_description": f"{task} {phrase}", "referral_expressions": {"pickup_obj_name": phrase}},
    }


def generate_benchmark(task: str, n_houses: int, episodes_per_house: int, seed: int,
                       name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Open or close episodes (JSON-ready EpisodeSpec dicts) and metadata, fully determined by the arguments."""
    if task not in ("open", "close"):
        raise ValueError(f"generate_articulated: unknown task {task!r} (can generate: open, close)")
    if n_houses < 1 or episodes_per_house < 1:
        raise ValueError("generate: n_houses and episodes_per_house must be at least 1")
    scene = ArticulatedTabletop()
    if n_houses > scene.n_houses():
        raise ValueError(f"generate: n_houses {n_houses} exceeds the {scene.n_houses()} articulated houses")
    order = np.random.default_rng([seed, 0x4855, 0x0C]).permutation(scene.n_houses())
    houses: list[int] = []
    for h in (int(h) for h in order):  # houses with at least one joint this task may target
        if _candidates(h, scene.metadata(h), task):
            houses.append(h)
        if len(houses) == n_houses:
            break
    houses.sort()
    episodes = [_episode(scene, h, i, seed, task) for h in houses for i in range(episodes_per_house)]
    description = (f"{task} articulated objects on the articulated tabletop: {n_houses} houses x "
                   f"{episodes_per_house} episodes, Franka Panda, exocentric + wrist camera "
                   f"(generator v{GENERATOR_VERSION}, seed {seed})")
    return episodes, benchmark_metadata(name, task, description, episodes, houses, episodes_per_house, seed,
                                        ARTICULATED_OBJECTS, GENERATOR_VERSION)
