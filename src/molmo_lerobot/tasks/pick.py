"""The pick task (a task plugin): lift the object and hold it, touching nothing but the robot.

Success (MolmoSpaces' ``PickTask``, see docs/success_rules.md): the object's height is at
least ``succ_pos_threshold`` (default 0.01 m) above ``task.pickup_obj_start_pose`` (its height at
the start when the episode gives no start pose) **and** it touches the robot and nothing else
(contacts between top-level bodies: no table, no other object).

Environment state (opt-in, privileged; robosuite's object state): the object's pose in the robot
base frame, ``object_x`` … ``object_qz`` (:func:`~molmo_lerobot.tasks.base.pose_in_base`), the
half extents of its bounding box in its own frame, ``object_half_x`` … ``object_half_z`` (which
grasp fits: a brick and a block of one height differ only here), and the vector from the robot's
TCP to the object in the base frame, ``tcp_to_object_x`` … ``tcp_to_object_z`` (how far the
gripper still has to go).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import Field

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.molmospaces import task_aliases
from molmo_lerobot.benchmark.schema import BaseTaskSpec, Pose7
from molmo_lerobot.sim import geometry
from molmo_lerobot.tasks.base import Task, TaskType, pose_in_base, pose_names, vector_in_base

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env

class PickTaskSpec(BaseTaskSpec):
    """Pick: lift the object at least ``succ_pos_threshold`` metres, touching only the robot."""

    pickup_obj_name: str
    pickup_obj_start_pose: Pose7
    pickup_obj_goal_pose: Pose7 | None = None
    receptacle_name: str | None = None
    succ_pos_threshold: float = Field(default=0.01, ge=0)  # metres


class PickTask(Task[PickTaskSpec]):
    """Pick ``spec.pickup_obj_name``."""

    environment_state_names = (*pose_names("object"), *(f"object_half_{c}" for c in "xyz"),
                               *(f"tcp_to_object_{c}" for c in "xyz"))

    def __init__(self, spec: PickTaskSpec, env: Env) -> None:
        name = spec.pickup_obj_name
        if not name:
            raise ValueError("task.pickup_obj_name: missing (a pick task needs the object to pick)")
        self.spec, self.env = spec, env
        self.object_name = name
        self.threshold = float(spec.succ_pos_threshold)
        self._object = env.body_id(name, "task.pickup_obj_name")
        self.object_bodies = env.subtree_bodies(name)
        self.start_height: float | None = None
        self.half_extents: np.ndarray | None = None

    def setup(self) -> None:
        self.start_height = float(self.spec.pickup_obj_start_pose[2])
        self.half_extents = geometry.half_extents_in_body(self.env.model, self.env.data, self._object)

    def lift(self) -> float:
        """Height gained since ``setup`` (metres)."""
        if self.start_height is None:
            raise RuntimeError("PickTask.setup() must run before success()")
        return float(self.env.data.xpos[self._object][2]) - self.start_height

    def success(self) -> bool:
        if self.lift() < self.threshold:
            return False
        touching = self.env.contact_bodies(self.object_bodies)
        return bool(touching) and touching <= self.env.robot.body_ids

    def reward(self) -> float:
        return 1.0 if self.success() else 0.0

    def environment_state(self) -> np.ndarray:
        if self.half_extents is None:
            raise RuntimeError("PickTask.setup() must run before environment_state()")
        d = self.env.data
        to_object = vector_in_base(self.env, d.xpos[self._object] - d.site_xpos[self.env.robot.tcp_site])
        return np.concatenate([pose_in_base(self.env, self._object), self.half_extents, to_object])


class PickTaskType(TaskType[PickTaskSpec]):
    name = "pick"
    aliases = ("molmo_lerobot.tasks.pick.PickTask", *task_aliases("pick"))
    spec_model = PickTaskSpec
    default_horizon_sec = 20.0

    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        return {"succ_pos_threshold": float(self.task_spec(spec).succ_pos_threshold)}

    def create(self, spec: EpisodeSpec, env: Env) -> PickTask:
        return PickTask(self.task_spec(spec), env)


@hookimpl
def molmo_task_types() -> list[TaskType[Any]]:
    return [PickTaskType()]
