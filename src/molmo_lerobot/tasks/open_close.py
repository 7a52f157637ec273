"""Open and close tasks on articulated objects (a task plugin: task types ``open`` and ``close``).

Both are MolmoSpaces' ``OpeningTask`` (``molmo_spaces/tasks/opening_tasks.py``), told apart by
``task.task_type``. The opening fraction of a joint is ``|q| / |range|`` (MolmoSpaces'
convention: every articulated joint closes at 0, its range runs from 0 to fully open).

* open: success when the largest opening fraction over the hinge and slide joints of
  ``task.pickup_obj_name`` — or, with ``task.any_inst_of_category``, of every articulated
  object of its category (scene metadata ``category``) — is at least ``task_success_threshold``
  (default 0.2). A zero-range (unlimited) joint turned away from 0 is skipped; one at exactly 0
  gives MolmoSpaces ``0 / 0 = NaN``, which their ``max`` keeps when it comes first (the object's
  first joint; with ``any_inst_of_category`` the first of all), and the check fails whatever the
  other joints do. ``task_rules=molmospaces`` (the default) judges so; ``task_rules=fixed`` skips
  every zero-range joint. Where the two differ the episode's ``parity_notes`` say so.
* close: success when ``1 -`` the opening fraction of the object's ``task.joint_index``-th
  articulated joint is at least ``task_success_threshold``; a zero-range joint never counts as
  closed (MolmoSpaces divides by the zero range).

The initial joint state is ``task.joint_start_position`` applied to ``task.joint_name`` (a list
gives its first value, as MolmoSpaces reads it); it is applied when the task is created, right
after the environment reset.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import mujoco
from pydantic import Field

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.molmospaces import task_aliases
from molmo_lerobot.benchmark.schema import BaseTaskSpec, Pose7
from molmo_lerobot.tasks.base import Task, TaskType

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env

_ARTICULATED = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


class OpenCloseTaskSpec(BaseTaskSpec):
    """Open / close an articulated object; success on the opening fraction of its joint."""

    pickup_obj_name: str
    pickup_obj_start_pose: Pose7
    articulation_object_name: str | None = None
    joint_name: str
    joint_index: int = 0
    joint_start_position: float | list[float]
    joint_goal_position: float | None = None
    task_success_threshold: float = Field(default=0.20, ge=0, le=1)  # opening fraction
    any_inst_of_category: bool = False


def opening_fraction(model: mujoco.MjModel, data: mujoco.MjData, joint: int) -> float:
    """``|q| / |range|`` of a hinge or slide joint (0 closed, 1 fully open; inf for a zero range)."""
    lo, hi = model.jnt_range[joint]
    span = abs(float(hi - lo))
    q = abs(float(data.qpos[model.jnt_qposadr[joint]]))
    return q / span if span > 0 else math.inf


def articulated_joints(env: Env, body_name: str) -> list[int]:
    """Hinge and slide joints of ``body_name``'s subtree, in model order."""
    m = env.model
    bodies = env.subtree_bodies(body_name)
    return [j for j in range(m.njnt) if int(m.jnt_bodyid[j]) in bodies and int(m.jnt_type[j]) in _ARTICULATED]


class OpenCloseTask(Task[OpenCloseTaskSpec]):
    """Open (``mode="open"``) or close (``mode="close"``) a joint of ``spec.pickup_obj_name``."""

    def __init__(self, spec: OpenCloseTaskSpec, env: Env, mode: str) -> None:
        if mode not in ("open", "close"):
            raise ValueError(f"task_type must be 'open' or 'close', got {mode!r}")
        t = self.spec = spec
        self.env, self.mode = env, mode
        self.object_name = t.pickup_obj_name
        self.threshold = float(t.task_success_threshold)
        env.body_id(self.object_name, "task.pickup_obj_name")
        m = env.model
        #: articulated joints of the object, in model order
        self.joints = articulated_joints(env, self.object_name)
        if not self.joints:
            raise ValueError(f"task.pickup_obj_name: {self.object_name!r} has no hinge or slide joint")
        self.joint = self._resolve_joint(t.joint_name)
        index = int(t.joint_index)
        if not 0 <= index < len(self.joints):
            raise ValueError(f"task.joint_index: {index} out of range ({self.object_name!r} has "
                             f"{len(self.joints)} articulated joints)")
        #: the joint the close rule judges (MolmoSpaces: the joint_index-th joint of the object)
        self.close_joint = self.joints[index]
        #: joints the open rule judges: the object's, or every articulated object's of its category,
        #: objects in model order (MolmoSpaces' scan of the top-level bodies)
        self.open_joints = list(self.joints)
        if t.any_inst_of_category:
            objects = env.scene_metadata.get("objects", {})
            category = objects.get(self.object_name, {}).get("category")
            if category is None:
                raise ValueError(f"task.any_inst_of_category: no category for {self.object_name!r} in the "
                                 "scene metadata")
            same = sorted((bid, name) for name, meta in objects.items() if meta.get("category") == category
                          and (bid := mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)) >= 0)
            self.open_joints = [j for _, name in same for j in articulated_joints(env, name)]
        self.start = t.joint_start_position

    def _resolve_joint(self, name: str) -> int:
        m = self.env.model
        for candidate in (name, f"{self.object_name}/{name}"):
            jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, candidate)
            if jid >= 0:
                if jid not in self.joints:
                    raise ValueError(f"task.joint_name: joint {candidate!r} is not a hinge/slide joint of "
                                     f"{self.object_name!r}")
                return jid
        names = [m.joint(j).name for j in self.joints]
        raise ValueError(f"task.joint_name: no joint {name!r} on {self.object_name!r} (joints: {', '.join(names)})")

    def apply_start_state(self) -> None:
        """Put ``joint_name`` at ``joint_start_position`` (its first value when a list) and recompute kinematics."""
        m, d = self.env.model, self.env.data
        if isinstance(self.start, list):
            if not self.start:
                raise ValueError("task.joint_start_position: empty list")
            q = float(self.start[0])
        else:
            q = float(self.start)
        lo, hi = m.jnt_range[self.joint]
        if not lo - 1e-9 <= q <= hi + 1e-9:
            raise ValueError(f"task.joint_start_position: {q} outside the range [{lo:g}, {hi:g}] of joint "
                             f"{m.joint(self.joint).name!r}")
        d.qpos[m.jnt_qposadr[self.joint]] = q
        d.qvel[m.jnt_dofadr[self.joint]] = 0.0
        mujoco.mj_forward(m, d)

    def setup(self) -> None:
        """Nothing to remember: the rule depends on the current joint state only."""

    def fraction(self) -> float:
        """The opening fraction our rule judges: max over the open rule's joints (zero ranges
        skipped), or of the close rule's joint."""
        m, d = self.env.model, self.env.data
        if self.mode == "open":
            fractions = [f for j in self.open_joints if math.isfinite(f := opening_fraction(m, d, j))]
            return max(fractions, default=0.0)
        return opening_fraction(m, d, self.close_joint)

    def nan_joint(self) -> str | None:
        """open: the zero-range joint at exactly 0 that comes first among the open rule's joints,
        which makes MolmoSpaces' fraction NaN (their ``max`` keeps a NaN it starts from); else None."""
        m, d = self.env.model, self.env.data
        for j in self.open_joints:
            if opening_fraction(m, d, j) != math.inf:
                return None  # a judged joint comes first
            if d.qpos[m.jnt_qposadr[j]] == 0.0:
                return m.joint(j).name
        return None

    def reward(self) -> float:
        """MolmoSpaces' reward: the opening fraction (open) or one minus it (close); our rule's fraction."""
        f = self.fraction()
        return f if self.mode == "open" else 1.0 - f

    def success(self) -> bool:
        if self.env.task_rules == "molmospaces" and self.mode == "open" and self.nan_joint() is not None:
            return False
        return self.reward() >= self.threshold

    def parity_notes(self) -> tuple[str, ...]:
        joint = self.nan_joint() if self.mode == "open" else None
        if joint is None or self.reward() < self.threshold:
            return ()
        other = "fixed" if self.env.task_rules == "molmospaces" else "molmospaces"
        verdict = "open" if other == "fixed" else "not open"
        return (f"open: zero-range joint {joint!r} at 0 comes first (MolmoSpaces' fraction is NaN); "
                f"task_rules={other} judges the final state {verdict}",)


class _OpenCloseType(TaskType[OpenCloseTaskSpec]):
    mode: str
    spec_model = OpenCloseTaskSpec
    default_horizon_sec = 30.0  # MolmoSpaces' table; the open/close v1 files carry 15 s

    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        return {"task_success_threshold": float(self.task_spec(spec).task_success_threshold)}

    def create(self, spec: EpisodeSpec, env: Env) -> OpenCloseTask:
        task = OpenCloseTask(self.task_spec(spec), env, self.mode)
        task.apply_start_state()
        return task


class OpenTaskType(_OpenCloseType):
    name = mode = "open"
    aliases = ("molmo_lerobot.tasks.open_close.OpenTask", *task_aliases("open"))


class CloseTaskType(_OpenCloseType):
    name = mode = "close"
    aliases = ("molmo_lerobot.tasks.open_close.CloseTask", *task_aliases("close"))


@hookimpl
def molmo_task_types() -> list[TaskType[Any]]:
    return [OpenTaskType(), CloseTaskType()]
