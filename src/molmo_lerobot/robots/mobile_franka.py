"""``mobile_franka``: MolmoSpaces' mobile Franka — the ``franka_droid`` arm and Robotiq on a box
base that drives holonomically over the floor (their ``MobileFrankaRobot`` /
``MobileFrankaRobotConfig``, ``molmo_spaces/robots/mobile_franka.py``).

Built as their ``add_robot_to_scene`` builds it, under the namespace ``robot_0/``:

* a body ``robot_0/base`` at ``task.robot_base_pose`` (roll and pitch must be zero) with a site
  ``robot_0/base_site`` at its origin and a box of ``base_size`` (:data:`BASE_SIZE`, their default
  ``[0.5, 0.5, 0.58]``) standing on it; the arm's ``fr3_link0`` (:mod:`molmo_lerobot.robots.franka_droid`:
  their model where installed, else the registry-built one) on the box's top centre;
* three joints on the base body: slides ``robot_0/base_x`` and ``robot_0/base_y`` along the world
  x and y axes (range ±:data:`BASE_RANGE` m) and a hinge ``robot_0/base_theta`` about z, each with
  its ``ref`` at the start pose, so their positions are the base's world x, y and yaw;
* their actuators: ``robot_0/base_x_act`` / ``robot_0/base_y_act`` drive the base site relative to a
  world site ``robot_0/world`` (site transmission, gear along x / y; kp :data:`BASE_XY_KP`, damping
  ratio 1, ctrl range ±:data:`BASE_RANGE`) and ``robot_0/base_theta_act`` the hinge (kp
  :data:`BASE_THETA_KP`, damping ratio 1, no ctrl range) — their ``holo_joint_planar_position``
  command mode.

Move groups, in their order: ``base`` (world x, y in metres and yaw in radians; a yaw target is
wrapped to within ±π of the current yaw, as their base group does), ``arm`` (7 joint positions)
and ``gripper`` (0 open … 1 closed). The base starts where ``task.robot_base_pose`` puts it, whatever
``robot.init_qpos["base"]`` says (``[]`` or three values): their JSON evaluation sets the base group
from ``init_qpos`` and then the base pose from ``robot_base_pose`` (``tasks/json_eval_task_sampler.py``,
``randomize_scene`` before ``_sample_task``); their files write ``[0, 0, 0]`` there.

The navigation camera ``head_camera`` is the robot's own (:data:`HEAD_CAMERA_POS` /
:data:`HEAD_CAMERA_QUAT` / :data:`HEAD_CAMERA_FOVY` on ``robot_0/base``: on a mast above the
base's centre, 1.65 m above the floor, looking ahead and 25° down, fov 75°: over the arm in its
start pose, which shows at the image's bottom edge); :mod:`molmo_lerobot.cameras.mobile`
renders it beside the wrist camera. MolmoSpaces' Franka has no head camera (their nav runs on
RB-Y1), so its pose is ours. Their base box is textured with their ``DarkWood2.png``, which is in
their assets; ours is the pedestal colour.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.robots.base import PEDESTAL_RGBA, RobotType, planar_base_range
from molmo_lerobot.robots.franka_droid import BASE_SIZE, NAMESPACE, FrankaDroid, FrankaDroidHandle, load_droid_spec

#: MolmoSpaces' ``base_control_params``: slide kp, hinge kp (damping ratio 1 on all) and the slides' range (m)
BASE_XY_KP, BASE_THETA_KP, BASE_DAMPING_RATIO, BASE_RANGE = 25000.0, 5000.0, 1.0, 25.0
#: the head camera on ``robot_0/base`` (MuJoCo camera: looks along -z, +y up): above the base's centre,
#: 1.65 m up, looking along the base's +x and pitched 25° down; vertical fov (deg)
HEAD_CAMERA_POS = (0.0, 0.0, 1.65)
HEAD_CAMERA_PITCH_DEG = 25.0
HEAD_CAMERA_FOVY = 75.0
BASE_JOINTS = ("base_x", "base_y", "base_theta")


def _head_camera_quat(pitch_deg: float) -> tuple[float, float, float, float]:
    """A camera looking along the body's +x, pitched ``pitch_deg`` down, its image up towards +z."""
    pitch = math.radians(pitch_deg)
    forward = np.array([math.cos(pitch), 0.0, -math.sin(pitch)])
    up = np.array([math.sin(pitch), 0.0, math.cos(pitch)])
    right = np.cross(forward, up)
    mat = np.column_stack([right, up, -forward])  # camera x, y, z in the body frame
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, mat.flatten())
    return tuple(float(v) for v in quat)  # type: ignore[return-value]


HEAD_CAMERA_QUAT = _head_camera_quat(HEAD_CAMERA_PITCH_DEG)


def _yaw(quat: Sequence[float]) -> float:
    """The yaw of a wxyz quaternion; ``ValueError`` if it rolls or pitches."""
    w, x, y, z = (float(v) for v in quat)
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.array([w, x, y, z]) / math.sqrt(w * w + x * x + y * y + z * z))
    if abs(mat[8] - 1.0) > 1e-6:
        raise ValueError(f"robot_base_pose: a mobile base stands upright (roll and pitch 0), got {list(quat)}")
    return math.atan2(mat[3], mat[0])


class MobileFrankaHandle(FrankaDroidHandle):
    """Move-group access to ``mobile_franka``: ``base`` here, ``arm`` and ``gripper`` as ``franka_droid``."""

    robot_name = "mobile_franka"

    def __init__(self, model: mujoco.MjModel, prefix: str = NAMESPACE) -> None:
        super().__init__(model, prefix)
        joints = [model.joint(f"{prefix}{name}").id for name in BASE_JOINTS]
        self._base_q = np.array([model.jnt_qposadr[j] for j in joints])
        self._base_v = np.array([model.jnt_dofadr[j] for j in joints])
        self._base_u = np.array([model.actuator(f"{prefix}{name}_act").id for name in BASE_JOINTS])
        self._base_body = model.body(f"{prefix}base").id
        self._base_lo = np.array([-np.inf] * 3)
        self._base_hi = np.array([np.inf] * 3)
        limited = model.actuator_ctrllimited[self._base_u].astype(bool)
        self._base_lo[limited] = model.actuator_ctrlrange[self._base_u[limited], 0]
        self._base_hi[limited] = model.actuator_ctrlrange[self._base_u[limited], 1]

    def _check(self, group: str) -> None:
        if group not in ("base", "arm", "gripper"):
            raise KeyError(f"{self.robot_name} has move groups 'base', 'arm' and 'gripper', not {group!r}")

    def qpos(self, data, group):
        return data.qpos[self._base_q].copy() if group == "base" else super().qpos(data, group)

    def qvel(self, data, group):
        return data.qvel[self._base_v].copy() if group == "base" else super().qvel(data, group)

    def joint_qpos(self, data, group):
        return self.qpos(data, group) if group == "base" else super().joint_qpos(data, group)

    def joint_qvel(self, data, group):
        return self.qvel(data, group) if group == "base" else super().joint_qvel(data, group)

    def set_qpos(self, data, group, values):
        if group != "base":
            return super().set_qpos(data, group, values)
        values = np.asarray(values, dtype=np.float64)
        if values.size:  # empty: stay at the start pose (the joints' reference positions)
            data.qpos[self._base_q] = values
        data.qvel[self._base_v] = 0.0
        self.command(data, group, data.qpos[self._base_q])
        return None

    def targets(self, data, group):
        return data.ctrl[self._base_u].copy() if group == "base" else super().targets(data, group)

    def base_pose(self, data):
        """The base body's world pose now (observations' ``robot_base_pose`` follow the robot)."""
        return np.concatenate([data.xpos[self._base_body], data.xquat[self._base_body]])

    def command_range(self, group):
        if group != "base":
            return super().command_range(group)
        return planar_base_range(self._base_lo, self._base_hi)

    def command(self, data, group, values):
        if group != "base":
            return super().command(data, group, values)
        target = np.clip(np.asarray(values, dtype=np.float64), self._base_lo, self._base_hi)
        yaw = float(data.qpos[self._base_q[2]])  # their base group: the yaw target within ±π of the yaw
        target[2] = yaw + (target[2] - yaw + math.pi) % (2 * math.pi) - math.pi
        data.ctrl[self._base_u] = target
        return None


def add_mobile_base(world: mujoco.MjSpec, pose: Sequence[float], base_size: Sequence[float]) -> mujoco.MjsFrame:
    """MolmoSpaces' holonomic base at ``pose`` (x, y, z, qw, qx, qy, qz): body, sites, box, the three
    base joints and their actuators (module docstring); returns the frame on the box's top."""
    x, y, z = (float(v) for v in pose[:3])
    yaw = _yaw(pose[3:])
    sx, sy, sz = (float(v) for v in base_size)
    body = world.worldbody.add_body(name=NAMESPACE + "base", pos=[x, y, z], quat=[float(v) for v in pose[3:]])
    body.add_site(name=NAMESPACE + "base_site", pos=[0.0, 0.0, 0.0])
    body.add_geom(name=NAMESPACE + "base/box", type=mujoco.mjtGeom.mjGEOM_BOX, size=[sx / 2, sy / 2, sz / 2],
                  pos=[0.0, 0.0, sz / 2], rgba=list(PEDESTAL_RGBA), group=0)
    body.add_camera(name=NAMESPACE + "head_camera", pos=list(HEAD_CAMERA_POS), quat=list(HEAD_CAMERA_QUAT),
                    fovy=HEAD_CAMERA_FOVY)
    world.worldbody.add_site(name=NAMESPACE + "world", pos=[0.0, 0.0, 0.005])
    c, s = math.cos(yaw), math.sin(yaw)
    for k, (name, ref) in enumerate((("base_x", x), ("base_y", y))):
        world_axis = np.eye(3)[k]  # the body frame's view of world x / y (their init_rot.inv())
        axis = [c * world_axis[0] + s * world_axis[1], -s * world_axis[0] + c * world_axis[1], 0.0]
        body.add_joint(name=NAMESPACE + name, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis,
                       range=[-BASE_RANGE, BASE_RANGE], ref=ref)
        gear = [0.0] * 6
        gear[k] = 1.0
        world.add_actuator(name=f"{NAMESPACE}{name}_act", target=NAMESPACE + "base_site", refsite=NAMESPACE + "world",
                           trntype=mujoco.mjtTrn.mjTRN_SITE, gear=gear, ctrlrange=[-BASE_RANGE, BASE_RANGE],
                           gaintype=mujoco.mjtGain.mjGAIN_FIXED, biastype=mujoco.mjtBias.mjBIAS_AFFINE,
                           gainprm=[BASE_XY_KP] + [0.0] * 9,
                           biasprm=[0.0, -BASE_XY_KP, BASE_DAMPING_RATIO] + [0.0] * 7)
    ref = math.degrees(yaw) if world.compiler.degree else yaw  # a hinge's ref is in the compiler's angle unit
    body.add_joint(name=NAMESPACE + "base_theta", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0.0, 0.0, 1.0], ref=ref)
    world.add_actuator(name=NAMESPACE + "base_theta_act", target=NAMESPACE + "base_theta",
                       trntype=mujoco.mjtTrn.mjTRN_JOINT, gaintype=mujoco.mjtGain.mjGAIN_FIXED,
                       biastype=mujoco.mjtBias.mjBIAS_AFFINE, gainprm=[BASE_THETA_KP] + [0.0] * 9,
                       biasprm=[0.0, -BASE_THETA_KP, BASE_DAMPING_RATIO] + [0.0] * 7)
    return body.add_frame(pos=[0.0, 0.0, sz])


class MobileFranka(FrankaDroid):
    """Franka + Robotiq on MolmoSpaces' holonomic box base; see the module docstring."""

    name = "mobile_franka"
    aliases = ("mobile_franka_droid",)  # their robot view's name
    move_groups: ClassVar[dict[str, int]] = {"base": 3, "arm": 7, "gripper": 1}
    joint_names: ClassVar[dict[str, list[str]]] = {"base": list(BASE_JOINTS), **FrankaDroid.joint_names}
    default_camera_system = "MobileFrankaCameraSystem"
    default_base_size = BASE_SIZE
    #: MolmoSpaces' MobileFrankaRobotConfig.init_qpos for arm and gripper; the base starts at robot_base_pose
    default_init_qpos: ClassVar[dict[str, list[float]]] = {"base": [], **FrankaDroid.default_init_qpos}

    def init_qpos(self, group: str, values: Sequence[float]) -> np.ndarray:
        """``base``: ``[]`` or three values, either way the base stays at ``robot_base_pose`` (module
        docstring); ``arm`` and ``gripper`` as ``franka_droid``."""
        if group == "base":
            if len(values) not in (0, 3):
                raise ValueError(f"expected [] or [x, y, yaw], got {len(values)} values")
            return np.zeros(0)
        return super().init_qpos(group, values)

    def base_size(self, robot_spec: object) -> tuple[float, float, float]:
        """The base box (``robot.base_size`` or :data:`BASE_SIZE`); a mobile base cannot be left out."""
        size = super().base_size(robot_spec)
        if size is None:
            raise ValueError("robot.base_size: the mobile base needs a box (three sizes), got null")
        return size

    def add_to(self, world: mujoco.MjSpec, base_pose: Sequence[float],
               base_size: Sequence[float] | None = None) -> None:
        """The base at ``base_pose`` (a box of ``base_size``), the arm on its top; :meth:`spec` is the arm alone."""
        top = add_mobile_base(world, self.base_pose(base_pose), base_size or BASE_SIZE)
        top.attach_body(load_droid_spec().body("fr3_link0"), NAMESPACE, "")

    def bind(self, model: mujoco.MjModel) -> MobileFrankaHandle:
        return MobileFrankaHandle(model, NAMESPACE)


@hookimpl
def molmo_robots() -> list[RobotType]:
    return [MobileFranka()]
