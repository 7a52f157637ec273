"""Door opening (a task plugin: task type ``door_opening``), MolmoSpaces' ``DoorOpeningTask``
(``molmo_spaces/tasks/opening_tasks.py``; its episode fields: ``DoorOpeningTaskSpec`` of their
benchmark schema, accepted unchanged).

* The door is the body ``task.door_body_name``; its hinge is the first hinge or slide joint of the
  body's subtree whose name does not contain ``handle`` (their ``Door.get_hinge_joint_index``);
  its handles are the subtree's leaf bodies (their ``_get_handle_leaf_body_ids``).
* Openness: ``clip((q - r0) / (r1 - r0), 0, 1)`` with ``[r0, r1]`` = ``task.articulated_joint_range``,
  or the hinge's own range where the episode gives none (their sampler fills it from the model).
* Success: openness ≥ ``task.door_openness_threshold`` (0.67) in the current state; reward: 1.0
  (their ``door_open_reward``) times success.
* Start state: the hinge at ``task.articulated_joint_reset_state[0]`` (0.0 where absent), applied
  when the task is created, right after the environment reset. MolmoSpaces sets it and judges the
  episode's range without checking either (``DoorOpeningTask.__init__``, ``get_door_open_percentage``),
  so a start outside the hinge's range, a reversed ``articulated_joint_range`` or a door already
  open past the threshold at the start runs here too, marked: the task's ``start_warnings`` (in
  the episode's result and ``results.json``), and ``molmo-bench validate`` warns of those the
  file alone shows (:meth:`DoorOpeningTaskType.spec_problems`).
* Prompt: "Push the door open" when turning the hinge 0.5 rad further carries the handle away from
  the robot base (``task.robot_base_pose``), else "Pull the door open" (their
  ``check_if_pushing_door``; they measure the grasp pose derived from the handle, a few centimetres
  off it, where :func:`is_pushing` measures the handle's own visual geom).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.molmospaces import task_aliases
from molmo_lerobot.benchmark.task_specs import DoorOpeningTaskSpec
from molmo_lerobot.sim.geometry import subtree
from molmo_lerobot.tasks.base import SpecProblem, Task, TaskType

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env

#: MolmoSpaces' ``door_open_reward``
OPEN_REWARD = 1.0
#: hinge turn (rad) MolmoSpaces tests the handle's motion with to tell push from pull
PUSH_TEST_DELTA = 0.5
PUSH_PROMPT, PULL_PROMPT = "Push the door open", "Pull the door open"
_ARTICULATED = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


def door_hinge(model: mujoco.MjModel, door: int) -> int:
    """The door's hinge joint id: the first hinge/slide joint of its subtree not named ``*handle*``."""
    bodies = subtree(model, door)
    for j in range(model.njnt):
        if int(model.jnt_bodyid[j]) in bodies and int(model.jnt_type[j]) in _ARTICULATED \
                and "handle" not in model.joint(j).name.lower():
            return j
    raise ValueError(f"task.door_body_name: {model.body(door).name!r} has no hinge joint (one not named *handle*)")


def door_handles(model: mujoco.MjModel, door: int) -> list[int]:
    """The door's handle bodies: the leaves of its subtree (the door body itself excluded)."""
    bodies = sorted(subtree(model, door))
    parents = {int(model.body_parentid[b]) for b in bodies}
    return [b for b in bodies if b != door and b not in parents]


def handle_point(model: mujoco.MjModel, data: mujoco.MjData, door: int) -> np.ndarray:
    """World position of the first handle's first visual geom (MolmoSpaces' ``Door.get_handle_pose``)."""
    for body in door_handles(model, door):
        for g in range(model.ngeom):
            if int(model.geom_bodyid[g]) == body and model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
                return data.geom_xpos[g].copy()
    raise ValueError(f"task.door_body_name: {model.body(door).name!r} has no handle with a visual geom")


def is_pushing(model: mujoco.MjModel, data: mujoco.MjData, door: int, robot_xyz: np.ndarray) -> bool:
    """Whether opening the door moves its handle away from ``robot_xyz`` (push) rather than towards it."""
    hinge = door_hinge(model, door)
    scratch = mujoco.MjData(model)
    scratch.qpos[:] = data.qpos
    mujoco.mj_kinematics(model, scratch)
    now = handle_point(model, scratch, door)
    scratch.qpos[model.jnt_qposadr[hinge]] += PUSH_TEST_DELTA
    mujoco.mj_kinematics(model, scratch)
    turned = handle_point(model, scratch, door)
    robot_xyz = np.asarray(robot_xyz, dtype=np.float64)
    return bool(np.linalg.norm(turned - robot_xyz) > np.linalg.norm(now - robot_xyz))


class DoorOpeningTask(Task[DoorOpeningTaskSpec]):
    """Open ``task.door_body_name`` to ``door_openness_threshold`` of its hinge range."""

    def __init__(self, spec: DoorOpeningTaskSpec, env: Env) -> None:
        t = self.spec = spec
        self.env = env
        self.door = env.body_id(t.door_body_name, "task.door_body_name")
        m = env.model
        self.hinge = door_hinge(m, self.door)
        self.qadr = int(m.jnt_qposadr[self.hinge])
        given = t.articulated_joint_range  # [closed, open] when given (its spec model checks the count)
        self.range = tuple(float(v) for v in (given if given is not None else m.jnt_range[self.hinge]))
        if self.range[1] == self.range[0]:
            raise ValueError(f"task.articulated_joint_range: empty range {list(self.range)}")
        self.threshold = float(t.door_openness_threshold)
        reset = t.articulated_joint_reset_state
        self.start = float(reset[0]) if reset is not None else 0.0
        self.pushing = False

    def apply_start_state(self) -> None:
        """Put the hinge at the reset state, recompute kinematics and tell push from pull."""
        m, d = self.env.model, self.env.data
        d.qpos[self.qadr] = self.start
        d.qvel[m.jnt_dofadr[self.hinge]] = 0.0
        mujoco.mj_forward(m, d)
        self.pushing = is_pushing(m, d, self.door, np.asarray(self.spec.robot_base_pose[:3]))
        warnings = [f"{field}: {what}" for field, what in start_warnings(self.range, self.start, self.threshold)]
        lo, hi = (float(v) for v in m.jnt_range[self.hinge])
        if m.jnt_limited[self.hinge] and not lo - 1e-9 <= self.start <= hi + 1e-9:
            warnings.insert(0, f"task.articulated_joint_reset_state: {self.start:g} is outside the range "
                               f"[{lo:g}, {hi:g}] of hinge {m.joint(self.hinge).name!r}")
        if self.success() and not any("step 0" in w for w in warnings):
            warnings.append(f"the door starts open past the threshold (openness {self.openness():.2f} >= "
                            f"{self.threshold:g}): the episode succeeds at step 0")
        self.start_warnings = tuple(warnings)

    def setup(self) -> None:
        """Nothing to remember: the rule depends on the current hinge state only."""

    def description(self) -> str:
        """MolmoSpaces' prompt for this episode."""
        return PUSH_PROMPT if self.pushing else PULL_PROMPT

    def openness(self) -> float:
        """The hinge's opening fraction of the episode's range, clipped to [0, 1]."""
        lo, hi = self.range
        return float(np.clip((float(self.env.data.qpos[self.qadr]) - lo) / (hi - lo), 0.0, 1.0))

    def success(self) -> bool:
        return self.openness() >= self.threshold

    def reward(self) -> float:
        return OPEN_REWARD * float(self.success())


def start_warnings(joint_range: Sequence[float] | None, start: float,
                   threshold: float) -> list[tuple[str, str]]:
    """``(field, what)`` the episode's own numbers show is odd about its start (MolmoSpaces runs it as it is)."""
    if joint_range is None or len(joint_range) != 2 or joint_range[0] == joint_range[1]:
        return []
    r0, r1 = (float(v) for v in joint_range)
    out = []
    if r1 < r0:
        out.append(("task.articulated_joint_range", f"[{r0:g}, {r1:g}] is reversed (closed above open)"))
    if not min(r0, r1) - 1e-9 <= start <= max(r0, r1) + 1e-9:
        out.append(("task.articulated_joint_reset_state",
                    f"{start:g} is outside articulated_joint_range [{r0:g}, {r1:g}]"))
    if float(np.clip((start - r0) / (r1 - r0), 0.0, 1.0)) >= threshold:
        out.append(("task.articulated_joint_reset_state", f"the door starts open past door_openness_threshold "
                                                          f"{threshold:g}: the episode succeeds at step 0"))
    return out


class DoorOpeningTaskType(TaskType[DoorOpeningTaskSpec]):
    name = "door_opening"
    aliases = ("molmo_lerobot.tasks.door_opening.DoorOpeningTask", *task_aliases("door_opening"))
    spec_model = DoorOpeningTaskSpec
    default_horizon_sec = 40.0  # their door data-generation config: 400 steps at 100 ms

    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        return {"door_openness_threshold": float(self.task_spec(spec).door_openness_threshold)}

    def spec_problems(self, spec: EpisodeSpec, scene_metadata: Callable[[], Mapping[str, Any] | None]
                      ) -> list[SpecProblem]:
        """Warnings (MolmoSpaces runs such episodes): a reversed range, a start outside it or already open."""
        t = self.task_spec(spec)
        start = float(t.articulated_joint_reset_state[0]) if t.articulated_joint_reset_state else 0.0
        return [SpecProblem(field, what, warning=True)
                for field, what in start_warnings(t.articulated_joint_range, start, float(t.door_openness_threshold))]

    def create(self, spec: EpisodeSpec, env: Env) -> DoorOpeningTask:
        task = DoorOpeningTask(self.task_spec(spec), env)
        task.apply_start_state()
        return task


@hookimpl
def molmo_task_types() -> list[TaskType[Any]]:
    return [DoorOpeningTaskType()]
