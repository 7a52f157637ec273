"""Robot descriptors: how a robot enters a scene (MjSpec) and how its move groups map to MuJoCo.

A :class:`RobotType` is what a robot plugin returns from ``molmo_robots()``. It adds the
robot to a world :class:`mujoco.MjSpec` at a base pose, then :meth:`RobotType.bind` gives a
:class:`RobotHandle` over the compiled model that reads and writes each move group
(``{"arm": 7, "gripper": 1}`` for a Franka) in the robot's public units.
"""

from __future__ import annotations

import hashlib
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import TYPE_CHECKING, ClassVar

import mujoco
import numpy as np

from molmo_lerobot.assets.builtin import HandGeometry
from molmo_lerobot.sim.geometry import subtree

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec


class RobotHandle(ABC):
    """A robot bound to one compiled model: state per move group and low-level commands."""

    @abstractmethod
    def qpos(self, data: mujoco.MjData, group: str) -> np.ndarray:
        """Joint positions of ``group`` in public units (gripper: 0 open … 1 closed)."""

    @abstractmethod
    def qvel(self, data: mujoco.MjData, group: str) -> np.ndarray:
        """Joint velocities of ``group`` in public units per second."""

    @abstractmethod
    def set_qpos(self, data: mujoco.MjData, group: str, values: np.ndarray) -> None:
        """Teleport ``group`` to ``values`` (zero velocity) and hold it there (ctrl = values)."""

    @abstractmethod
    def targets(self, data: mujoco.MjData, group: str) -> np.ndarray:
        """The position targets currently commanded to ``group``."""

    @abstractmethod
    def command(self, data: mujoco.MjData, group: str, values: np.ndarray) -> None:
        """Write position targets for ``group`` (clipped to the actuator range) into ``data.ctrl``.

        The map from ``values`` to ``ctrl`` must be affine (up to clipping): with
        ``timing.control=ramp`` the environment interpolates controller ticks in ctrl space.
        """

    def command_range(self, group: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The bounds :meth:`command` clips ``group``'s targets to (what an action means there); None
        where this robot does not say (the Gymnasium env's ``action_space`` is then unbounded there)."""
        return None

    def joint_qpos(self, data: mujoco.MjData, group: str) -> np.ndarray:
        """``group``'s joints in their own units (rad, m), as MolmoSpaces' ``qpos`` reports them."""
        return self.qpos(data, group)

    def base_pose(self, data: mujoco.MjData) -> np.ndarray | None:
        """The base's world pose now (x, y, z, qw, qx, qy, qz) for a robot that moves it; ``None`` for a
        fixed base (it stays at the episode's ``robot_base_pose``)."""
        return None

    def joint_qvel(self, data: mujoco.MjData, group: str) -> np.ndarray:
        """Their velocities, as MolmoSpaces' ``qvel`` reports them."""
        return self.qvel(data, group)

    @property
    @abstractmethod
    def tcp_site(self) -> int:
        """Site id of the tool centre point (origin between the finger pads, +z approach, +y fingers)."""

    @property
    @abstractmethod
    def body_ids(self) -> frozenset[int]:
        """Ids of every body that belongs to the robot (for contact tests)."""


def planar_base_range(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A holonomic base's (x, y, yaw) target bounds: its yaw target, unbounded (it is taken within ±π
    of the current yaw), as a heading in [-π, π]."""
    lo, hi = np.array(lo, dtype=np.float64), np.array(hi, dtype=np.float64)
    lo[2], hi[2] = max(lo[2], -math.pi), min(hi[2], math.pi)
    return lo, hi


class ArmGripperHandle(RobotHandle):
    """A position-controlled arm (move group ``arm``) plus one gripper value (``gripper``,
    0 open … 1 closed). The arm half lives here; a subclass maps the gripper value onto its
    hand's joints and actuators (the ``_gripper_*`` methods)."""

    robot_name: str
    #: qpos / qvel addresses of the gripper joints MolmoSpaces' gripper move group lists (set by subclasses)
    _grip_q: np.ndarray
    _grip_v: np.ndarray

    def __init__(self, model: mujoco.MjModel, arm_joints: Sequence[str], arm_actuators: Sequence[str],
                 tcp_site: str, root_body: str) -> None:
        joints = [model.joint(name).id for name in arm_joints]
        self._arm_q = np.array([model.jnt_qposadr[j] for j in joints])
        self._arm_v = np.array([model.jnt_dofadr[j] for j in joints])
        self._arm_u = np.array([model.actuator(name).id for name in arm_actuators])
        self._lo = model.actuator_ctrlrange[self._arm_u, 0].copy()
        self._hi = model.actuator_ctrlrange[self._arm_u, 1].copy()
        self._tcp = model.site(tcp_site).id
        self._bodies = subtree(model, model.body(root_body).id)

    def _check(self, group: str) -> None:
        if group not in ("arm", "gripper"):
            raise KeyError(f"{self.robot_name} has move groups 'arm' and 'gripper', not {group!r}")

    def qpos(self, data, group):
        self._check(group)
        return data.qpos[self._arm_q].copy() if group == "arm" else np.array([self._gripper_qpos(data)])

    def qvel(self, data, group):
        self._check(group)
        return data.qvel[self._arm_v].copy() if group == "arm" else np.array([self._gripper_qvel(data)])

    def joint_qpos(self, data, group):
        self._check(group)
        return data.qpos[self._arm_q if group == "arm" else self._grip_q].copy()

    def joint_qvel(self, data, group):
        self._check(group)
        return data.qvel[self._arm_v if group == "arm" else self._grip_v].copy()

    def set_qpos(self, data, group, values):
        self._check(group)
        values = np.asarray(values, dtype=np.float64)
        if group == "arm":
            data.qpos[self._arm_q] = values
            data.qvel[self._arm_v] = 0.0
        else:
            self._gripper_set_qpos(data, float(np.clip(values[0], 0.0, 1.0)))
        self.command(data, group, values)

    def targets(self, data, group):
        self._check(group)
        return data.ctrl[self._arm_u].copy() if group == "arm" else np.array([self._gripper_target(data)])

    def command_range(self, group):
        self._check(group)
        return (self._lo.copy(), self._hi.copy()) if group == "arm" else (np.zeros(1), np.ones(1))

    def command(self, data, group, values):
        self._check(group)
        values = np.asarray(values, dtype=np.float64)
        if group == "arm":
            data.ctrl[self._arm_u] = np.clip(values, self._lo, self._hi)
        else:
            self._gripper_command(data, float(np.clip(values[0], 0.0, 1.0)))

    @property
    def tcp_site(self) -> int:
        return self._tcp

    @property
    def body_ids(self) -> frozenset[int]:
        return self._bodies

    @abstractmethod
    def _gripper_qpos(self, data: mujoco.MjData) -> float:
        """The gripper's opening, 0 open … 1 closed."""

    @abstractmethod
    def _gripper_qvel(self, data: mujoco.MjData) -> float:
        """Its rate of closing per second."""

    @abstractmethod
    def _gripper_set_qpos(self, data: mujoco.MjData, closed: float) -> None:
        """Teleport the hand's joints to ``closed`` (0 … 1) at rest."""

    @abstractmethod
    def _gripper_target(self, data: mujoco.MjData) -> float:
        """The commanded closing, 0 … 1, read back from ``data.ctrl``."""

    @abstractmethod
    def _gripper_command(self, data: mujoco.MjData, closed: float) -> None:
        """Write the actuator targets for ``closed`` (0 … 1)."""


#: The largest pedestal side (metres): MolmoSpaces' are under 1 m; a kilometre-wide box breaks the physics.
MAX_BASE_SIZE_M = 5.0


def parse_base_size(value: object) -> tuple[float, float, float] | None:
    """A ``base_size`` as given (``null`` or three positive sizes in metres, each at most
    :data:`MAX_BASE_SIZE_M`); ``ValueError`` otherwise."""
    if value is None:
        return None
    numbers = isinstance(value, list | tuple) and all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    size = tuple(float(v) for v in value) if numbers and isinstance(value, list | tuple) else ()
    if len(size) != 3 or not all(math.isfinite(v) and 0 < v <= MAX_BASE_SIZE_M for v in size):
        raise ValueError(f"base_size must be null or three positive sizes in metres [x, y, z] "
                         f"(each at most {MAX_BASE_SIZE_M:g}), got {value!r}")
    return size[0], size[1], size[2]


#: the pedestal's colour (MolmoSpaces textures theirs with a dark wood)
PEDESTAL_RGBA = (0.33, 0.24, 0.17, 1.0)


def add_mount(world: mujoco.MjSpec, name: str, pose: Sequence[float],
              base_size: Sequence[float] | None) -> mujoco.MjsFrame:
    """MolmoSpaces' robot mount (their ``add_robot_to_scene``): a body ``name`` at ``pose``
    (x, y, z, qw, qx, qy, qz) with a box pedestal of ``base_size`` (full x, y, z extents,
    metres) standing on it; returns the frame on the pedestal's top where the arm's root is
    attached (at the body's origin without a pedestal)."""
    body = world.worldbody.add_body(name=name, pos=list(pose[:3]), quat=list(pose[3:]))
    if base_size is None:
        return body.add_frame()
    x, y, z = (float(v) for v in base_size)
    body.add_geom(name=name + "/pedestal", type=mujoco.mjtGeom.mjGEOM_BOX, size=[x / 2, y / 2, z / 2],
                  pos=[0.0, 0.0, z / 2], rgba=list(PEDESTAL_RGBA), group=0)
    return body.add_frame(pos=[0.0, 0.0, z])


class RobotType(ABC):
    """A robot plugin's descriptor, keyed by ``name`` and ``aliases`` (episode ``robot.robot_name``)."""

    name: str
    aliases: tuple[str, ...] = ()
    #: move group -> action dimension
    move_groups: ClassVar[dict[str, int]]
    #: move group -> public joint names (no "/": they become LeRobot feature names)
    joint_names: ClassVar[dict[str, list[str]]]
    #: groups of the robot that take no actions (group -> size): set from ``init_qpos`` at reset and held
    held_groups: ClassVar[dict[str, int]] = {}
    #: move group (and held group) -> default initial positions, used where an episode gives none
    default_init_qpos: ClassVar[dict[str, list[float]]]
    #: camera system for episodes that name no cameras and no ``source.camera_system_class``
    default_camera_system: str | None = None
    #: MolmoSpaces' ``base_size``: the box pedestal (x, y, z extents, metres) between the base
    #: pose and the arm's root, where an episode gives no ``robot.base_size``; None: no pedestal
    default_base_size: tuple[float, float, float] | None = None
    #: the robot whose hand this one carries: grasp libraries and hand geometry are looked up by it
    #: (None: its own name); a new version of a robot with the same gripper and TCP names the old one
    hand_of: str | None = None
    #: its gripper seen from the TCP (finger reach, span), what scripted grasping plans with;
    #: None: a robot whose hand the scripted experts do not know (they refuse it)
    hand_geometry: HandGeometry | None = None

    @property
    def hand(self) -> str:
        """The name grasps and hand geometry are kept under for this robot's gripper."""
        return self.hand_of or self.name

    def init_qpos(self, group: str, values: Sequence[float]) -> np.ndarray:
        """An episode's ``robot.init_qpos[group]`` in public units; ``ValueError`` if it does not fit."""
        size = self.move_groups[group] if group in self.move_groups else self.held_groups[group]
        if len(values) != size:
            raise ValueError(f"expected {size} values, got {len(values)}")
        return np.asarray(values, dtype=np.float64)

    def set_init_qpos(self, handle: RobotHandle, data: mujoco.MjData, group: str, values: Sequence[float]) -> None:
        """Start ``group`` at an episode's ``robot.init_qpos[group]`` in freshly reset ``data``: by default
        :meth:`init_qpos`'s public values through ``handle.set_qpos``; ``ValueError`` if they do not fit."""
        handle.set_qpos(data, group, self.init_qpos(group, values))

    def configured(self, settings: object) -> RobotType:
        """This robot under the run's MolmoSpaces settings (``settings.assets_dir``: where a robot
        whose model is in their assets finds it); most robots take none."""
        return self

    @abstractmethod
    def spec(self) -> mujoco.MjSpec:
        """A standalone spec of the robot with its base at the origin (also used for IK)."""

    def model_sha256(self) -> str:
        """SHA-256 of the robot's model as built here: every array of its compiled :meth:`spec` (bodies,
        joints, actuators, meshes' vertices, names), not where its asset files lie nor the meshes' hull
        polygons MuJoCo derives from their vertices (qhull's, which vary with the models the process
        compiled before); what a run records of the robot that ran."""
        model = self.spec().compile()
        digest = hashlib.sha256()
        for name in sorted(dir(model)):
            value = getattr(model, name)
            if (not name.startswith(("_", "mesh_poly")) and "path" not in name
                    and isinstance(value, np.ndarray)):
                digest.update(name.encode() + b"\0" + np.ascontiguousarray(value).tobytes())
        return digest.hexdigest()

    @staticmethod
    def base_pose(values: Sequence[float]) -> list[float]:
        """An episode's ``robot_base_pose`` as 7 floats; ``ValueError`` if it has another length."""
        pose = [float(v) for v in values]
        if len(pose) != 7:
            raise ValueError(f"robot_base_pose needs 7 values (x, y, z, qw, qx, qy, qz), got {len(pose)}")
        return pose

    def base_size(self, robot_spec: object) -> tuple[float, float, float] | None:
        """The pedestal of an episode's robot (its ``RobotSpec``): ``robot.base_size`` where the
        episode gives one (``null``: none), else :attr:`default_base_size`; ``ValueError`` if
        it is not three positive sizes."""
        extra = getattr(robot_spec, "model_extra", None) or {}
        if "base_size" not in extra:
            return self.default_base_size
        return parse_base_size(extra["base_size"])

    def place(self, world: mujoco.MjSpec, episode: EpisodeSpec) -> None:
        """Add the robot to ``world`` where ``episode`` puts it: at
        ``task.robot_base_pose``, on the pedestal of :meth:`base_size`."""
        pose, size = episode.task.robot_base_pose, self.base_size(episode.robot)
        if size is None:
            self.add_to(world, pose)  # robots of older plugins take no base_size
        else:
            self.add_to(world, pose, size)

    @abstractmethod
    def add_to(self, world: mujoco.MjSpec, base_pose: Sequence[float],
               base_size: Sequence[float] | None = None) -> None:
        """Attach the robot to ``world`` at ``base_pose`` (x, y, z, qw, qx, qy, qz), on a
        pedestal of ``base_size`` (see :func:`add_mount`) unless it is None."""

    @abstractmethod
    def bind(self, model: mujoco.MjModel) -> RobotHandle:
        """Resolve the robot's joints, actuators and sites in a compiled model that contains it."""
