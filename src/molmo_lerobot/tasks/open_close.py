"""Open and close tasks on articulated objects (a task plugin: task types ``open`` and ``close``).

Both are MolmoSpaces' ``OpeningTask``, told apart by ``task.task_type``. The opening fraction
of a joint is ``|q - q_closed| / |range|`` with ``q_closed = 0`` (MolmoSpaces' convention:
every articulated joint closes at 0, its range runs from 0 to fully open).

* open: success when the largest opening fraction over the articulated joints of
  ``task.pickup_obj_name`` is at least ``task_success_threshold`` (default 0.2);
* close: success when ``1 -`` the opening fraction of ``task.joint_name`` is at least
  ``task_success_threshold`` (default 0.2).

The episode's initial joint state is ``task.joint_start_position`` (a float for
``joint_name``, or one value per articulated joint of the object in model order); it is
applied when the task is created, right after the environment reset.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import mujoco

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.molmospaces import task_aliases
from molmo_lerobot.tasks.base import Task, TaskType

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env

DEFAULT_THRESHOLD = 0.20
_ARTICULATED = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


def opening_fraction(model: mujoco.MjModel, data: mujoco.MjData, joint: int) -> float:
    """``|q| / |range|`` of a hinge or slide joint (0 closed, 1 fully open)."""
    lo, hi = model.jnt_range[joint]
    span = abs(float(hi - lo))
    if span <= 0:
        raise ValueError(f"joint {model.joint(joint).name!r} has no range; cannot measure how open it is")
    return abs(float(data.qpos[model.jnt_qposadr[joint]])) / span


class OpenCloseTask(Task):
    """Open (``mode="open"``) or close (``mode="close"``) a joint of ``spec.task.pickup_obj_name``."""

    def __init__(self, spec: EpisodeSpec, env: Env, mode: str) -> None:
        if mode not in ("open", "close"):
            raise ValueError(f"task_type must be 'open' or 'close', got {mode!r}")
        t = spec.task
        self.env, self.mode = env, mode
        self.object_name = t.pickup_obj_name
        self.threshold = float(getattr(t, "task_success_threshold", DEFAULT_THRESHOLD))
        env.body_id(self.object_name, "task.pickup_obj_name")
        m = env.model
        bodies = env.subtree_bodies(self.object_name)
        #: articulated joints of the object, in model order
        self.joints = [j for j in range(m.njnt)
                       if int(m.jnt_bodyid[j]) in bodies and int(m.jnt_type[j]) in _ARTICULATED]
        if not self.joints:
            raise ValueError(f"task.pickup_obj_name: {self.object_name!r} has no hinge or slide joint")
        self.joint = self._resolve_joint(t.joint_name)
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
        """Put the joint(s) at ``joint_start_position`` (inside the joint range) and recompute kinematics."""
        m, d = self.env.model, self.env.data
        values = self.start if isinstance(self.start, list) else None
        if values is not None and len(values) != len(self.joints):
            raise ValueError(f"task.joint_start_position: {len(values)} values for the {len(self.joints)} "
                             f"articulated joints of {self.object_name!r}")
        pairs = zip(self.joints, values, strict=True) if values is not None else [(self.joint, float(self.start))]
        for j, q in pairs:
            lo, hi = m.jnt_range[j]
            if not lo - 1e-9 <= q <= hi + 1e-9:
                raise ValueError(f"task.joint_start_position: {q} outside the range [{lo:g}, {hi:g}] of joint "
                                 f"{m.joint(j).name!r}")
            d.qpos[m.jnt_qposadr[j]] = q
            d.qvel[m.jnt_dofadr[j]] = 0.0
        mujoco.mj_forward(m, d)

    def setup(self) -> None:
        """Nothing to remember: the rule depends on the current joint state only."""

    def fraction(self) -> float:
        """The opening fraction the rule judges: max over the object's joints (open), of the joint (close)."""
        m, d = self.env.model, self.env.data
        if self.mode == "open":
            return max(opening_fraction(m, d, j) for j in self.joints)
        return opening_fraction(m, d, self.joint)

    def reward(self) -> float:
        """MolmoSpaces' reward: the opening fraction (open) or one minus it (close)."""
        f = self.fraction()
        return f if self.mode == "open" else 1.0 - f

    def success(self) -> bool:
        return self.reward() >= self.threshold


class _OpenCloseType(TaskType):
    mode: str
    default_horizon_sec = 15.0

    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        return {"task_success_threshold": float(getattr(spec.task, "task_success_threshold", DEFAULT_THRESHOLD))}

    def create(self, spec: EpisodeSpec, env: Env) -> OpenCloseTask:
        for field in ("pickup_obj_name", "joint_name", "joint_start_position"):
            if getattr(spec.task, field, None) is None:
                raise ValueError(f"task.{field}: missing (an {self.mode} task needs it)")
        task = OpenCloseTask(spec, env, self.mode)
        task.apply_start_state()
        return task


class OpenTaskType(_OpenCloseType):
    name = mode = "open"
    aliases = ("molmo_lerobot.tasks.open_close.OpenTask", *task_aliases("open"))


class CloseTaskType(_OpenCloseType):
    name = mode = "close"
    aliases = ("molmo_lerobot.tasks.open_close.CloseTask", *task_aliases("close"))


@hookimpl
def molmo_task_types() -> list[TaskType]:
    return [OpenTaskType(), CloseTaskType()]
