"""Deterministic open/close v2 benchmarks: LIBERO fixtures in the textured rooms (``libero_fixture_rooms``).

``molmo-bench generate v2 --task open --houses 25 --episodes-per-house 4 --seed 0 --name open_v2``
(and ``--task close``). The v1 open/close tasks
(:mod:`molmo_lerobot.content.articulated.generate`) in the v2 setting: per episode, a house with
at least one joint the task may target (close: slide joints only, as v1), one joint of its fixture,
the joint's start state in ``task.joint_start_position`` (closed for open; 95–100 % open for close),
the robot's start pose (:data:`~molmo_lerobot.content.libero.episode_fields.READY_ARM`, small joint jitter),
franka_droid with the DROID cameras (``cameras: []``, the camera system builds them). Episodes use
MolmoSpaces' ``OpeningTask`` with ``task_type`` open/close and the v1 success threshold. Language
names the fixture and its part from the metadata: "open the middle drawer of the yellow cabinet",
"close the top drawer of the white cabinet". Same arguments, same JSON.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from molmo_lerobot.benchmark.output import benchmark_metadata, rounded
from molmo_lerobot.content.articulated.generate import CLOSE_KINDS, CLOSE_START, TASK_CLS, THRESHOLD
from molmo_lerobot.content.libero.episode_fields import CAMERA_SYSTEM, episode_fields, start_arm
from molmo_lerobot.content.libero.fixture_rooms import LiberoFixtureRooms
from molmo_lerobot.content.libero.fixtures import LIBERO_FIXTURES

GENERATOR_VERSION = 2
TASKS = ("open", "close")
HORIZON_SEC = 15.0


def _joints(scene: LiberoFixtureRooms, house: int, task: str) -> list[str]:
    """Joints of the house's fixture an episode of ``task`` may target."""
    return [j.name for j in scene.fixture(house).joints if task == "open" or j.kind in CLOSE_KINDS]


def phrase(uid: str, joint: str) -> str:
    """What the instruction calls ``joint`` of fixture ``uid``: "the top drawer of the white cabinet"."""
    fx = LIBERO_FIXTURES[uid]
    if len(fx.joints) == 1:
        return f"the {fx.description}"
    return f"the {fx.joint(joint).label} of the {fx.description}"


def _episode(scene: LiberoFixtureRooms, house: int, index: int, seed: int, task: str) -> dict[str, Any]:
    rng = np.random.default_rng([seed, house, index, 0x0C2])
    meta = scene.metadata(house)
    fx = scene.fixture(house)
    candidates = _joints(scene, house, task)
    joint = candidates[int(rng.integers(len(candidates)))]
    info = fx.joint(joint)
    start = 0.0 if task == "open" else info.open_q * float(rng.uniform(*CLOSE_START))
    arm = start_arm(rng)
    words = phrase(fx.uid, joint)
    return {
        **episode_fields(scene.name, house, rng, arm, {}),
        "task": {
            "task_cls": TASK_CLS,
            "task_type": task,
            "robot_base_pose": [rounded(v) for v in meta["robot_base_pose"]],
            "pickup_obj_name": fx.uid,
            "pickup_obj_start_pose": [rounded(v) for v in meta["objects"][fx.uid]["default_pose"]],
            "articulation_object_name": fx.uid,
            "joint_name": meta["objects"][fx.uid]["joints"][joint]["joint"],
            "joint_index": [j.name for j in fx.joints].index(joint),
            "joint_start_position": rounded(start),
            "task_success_threshold": THRESHOLD,
            "task_horizon_sec": HORIZON_SEC,
        },
        "task_relevant_objects": [fx.uid],
        "language": {"task_description": f"{task} {words}", "referral_expressions": {"pickup_obj_name": words}},
    }


def generate_benchmark(task: str, n_houses: int, episodes_per_house: int, seed: int,
                       name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Open or close episodes (JSON-ready EpisodeSpec dicts) and metadata, fully determined by the arguments."""
    if task not in TASKS:
        raise ValueError(f"generate_articulated (v2): unknown task {task!r} (can generate: {', '.join(TASKS)})")
    if n_houses < 1 or episodes_per_house < 1:
        raise ValueError("generate_articulated (v2): n_houses and episodes_per_house must be at least 1")
    scene = LiberoFixtureRooms()
    houses: list[int] = []
    for h in (int(h) for h in np.random.default_rng([seed, 0x4855, 0x0C2]).permutation(scene.n_houses())):
        if _joints(scene, h, task):
            houses.append(h)
        if len(houses) == n_houses:
            break
    houses.sort()
    episodes = [_episode(scene, h, i, seed, task) for h in houses for i in range(episodes_per_house)]
    styles = [scene.metadata(h)["style"] for h in houses]
    fixtures = [scene.fixture(h).uid for h in houses]
    description = (f"{task} LIBERO fixtures in textured LIBERO rooms: {n_houses} houses x {episodes_per_house} "
                   f"episodes, franka_droid, DROID cameras (generator v{GENERATOR_VERSION}, seed {seed})")
    meta = benchmark_metadata(name, task, description, episodes, houses, episodes_per_house, seed, LIBERO_FIXTURES,
                              GENERATOR_VERSION,
                              room_style_counts={s: styles.count(s) for s in sorted(set(styles))},
                              fixture_counts={f: fixtures.count(f) for f in sorted(set(fixtures))})
    meta["camera_system_class"] = CAMERA_SYSTEM
    return episodes, meta
