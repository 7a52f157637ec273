"""Task types: the success rule (and reward) of an episode, evaluated every policy step.

A :class:`TaskType` is what a task plugin returns from ``molmo_task_types()``; it is keyed
by ``name`` and ``aliases`` (MolmoSpaces' dotted ``task_cls`` paths) and owns ``spec_model``,
the pydantic model its episodes' ``task`` is validated with. ``create(spec, env)`` returns a
:class:`Task` bound to one episode's environment. Both are generic over that model
(``TaskType[PickTaskSpec]``), so a task reads its spec's fields, defaults included, as typed
attributes (:meth:`TaskType.task_spec`). A task never imports its scripted
expert: experts register for the task types they serve (hook ``molmo_experts``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import mujoco
import numpy as np

from molmo_lerobot.benchmark.schema import BaseTaskSpec, GenericTaskSpec

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env


class Task[SpecT: BaseTaskSpec](ABC):
    """One episode's task. ``setup`` runs after ``env.reset``; ``success`` after every policy step."""

    #: the episode's ``task``, as its task type's spec model
    spec: SpecT

    @abstractmethod
    def setup(self) -> None:
        """Remember the start state the success rule compares against."""

    @abstractmethod
    def success(self) -> bool:
        """Whether the task is solved in the current simulator state."""

    def reward(self) -> float | None:
        """A per-step reward, or ``None`` when the task defines none."""
        return None

    #: what is odd about the episode's start that MolmoSpaces accepts as it is (a joint started
    #: outside its range, a task already solved at the start): recorded in the episode's result
    #: (``start_warnings``) and listed in ``results.json``; set when the task is created
    start_warnings: tuple[str, ...] = ()

    def parity_notes(self) -> tuple[str, ...]:
        """Where the other rules of ``env.task_rules`` (MolmoSpaces' or our corrected one) would judge the
        current state otherwise, one line each; read at the episode's end into its result
        (``parity_notes``) and counted in ``results.json``. Empty where the rules agree."""
        return ()

    #: the names of :meth:`environment_state`'s values; empty: the task defines no environment state
    environment_state_names: tuple[str, ...] = ()

    def environment_state(self) -> np.ndarray:
        """Privileged simulator ground truth about the task's objects (LeRobot's
        ``observation.environment_state``), named by :attr:`environment_state_names`; the same
        names and meaning in every episode of the task type."""
        raise NotImplementedError(f"task {type(self).__name__} defines no environment state")


def pose_names(prefix: str) -> tuple[str, ...]:
    """The names of a pose's 7 values: ``<prefix>_x`` … ``<prefix>_qz``."""
    return tuple(f"{prefix}_{c}" for c in ("x", "y", "z", "qw", "qx", "qy", "qz"))


def vector_in_base(env: Env, v: np.ndarray) -> np.ndarray:
    """World vector ``v`` in the robot base frame's axes (``env.base_pose``)."""
    inv, out = np.zeros(4), np.zeros(3)
    mujoco.mju_negQuat(inv, env.base_pose[3:])
    mujoco.mju_rotVecQuat(out, np.asarray(v, dtype=np.float64), inv)
    return out


def pose_in_base(env: Env, body: int) -> np.ndarray:
    """``body``'s pose ``[x, y, z, qw, qx, qy, qz]`` in the robot base frame (``env.base_pose``),
    its quaternion's sign fixed by ``qw >= 0`` (one value per orientation)."""
    base = env.base_pose
    inv = np.zeros(4)
    mujoco.mju_negQuat(inv, base[3:])
    pos, quat = np.zeros(3), np.zeros(4)
    mujoco.mju_rotVecQuat(pos, env.data.xpos[body] - base[:3], inv)
    mujoco.mju_mulQuat(quat, inv, env.data.xquat[body])
    quat /= np.linalg.norm(quat)
    return np.concatenate([pos, -quat if quat[0] < 0 else quat])


@dataclass(frozen=True)
class SpecProblem:
    """A problem of an episode's ``field`` a task type finds; a ``warning`` does not stop it running."""

    field: str
    message: str
    warning: bool = False


class TaskType[SpecT: BaseTaskSpec](ABC):
    """A task plugin's descriptor."""

    name: str
    aliases: tuple[str, ...] = ()
    #: the model of ``EpisodeSpec.task`` (a :class:`BaseTaskSpec` subclass with this task's fields);
    #: a task type that sets none takes its fields as given (:class:`GenericTaskSpec`)
    spec_model: type[SpecT] = cast("type[SpecT]", GenericTaskSpec)
    #: horizon used when neither the CLI nor the episode (``task_horizon_sec``) gives one
    default_horizon_sec: float

    def task_spec(self, spec: EpisodeSpec) -> SpecT:
        """``spec.task`` as :attr:`spec_model` (validated with it where the episode was parsed with
        another model); a ``pydantic.ValidationError`` (a ``ValueError``) names the field that does not fit."""
        if isinstance(spec.task, self.spec_model):
            return spec.task
        return self.spec_model.model_validate(spec.task.model_dump())

    @abstractmethod
    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        """The success thresholds this episode is judged by (reported in results.json)."""

    def spec_problems(self, spec: EpisodeSpec, scene_metadata: Callable[[], Mapping[str, Any] | None]
                      ) -> list[SpecProblem]:
        """What only this task type can tell is wrong with ``spec`` before any simulation
        (``scene_metadata()``: its house's metadata, ``None`` where not at hand); none by default."""
        return []

    @abstractmethod
    def create(self, spec: EpisodeSpec, env: Env) -> Task[SpecT]:
        """A task instance for this episode; raise ``ValueError`` naming the field if the spec does not fit."""
