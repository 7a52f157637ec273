"""Franka Emika Panda with its parallel gripper, loaded from the installed gymnasium-robotics package.

The MJCF, meshes and actuators come from ``gymnasium_robotics/envs/assets/kitchen_franka``
at run time (nothing is copied into this repository). At load time the spec is adjusted
with MjSpec so that it behaves like the real arm and like DROID data:

* joints 6 and 7 use the standard Panda zero positions and limits (the kitchen model
  rotates their frames by 90° and 45°; only the joint zero moves, the geometry does not);
* every body has gravity compensation, as the real arm's controller does;
* the arm joints lose the kitchen model's heavy damping (100 N·m·s/rad, more than the
  87 N·m the motors may apply at 1 rad/s) and the actuators get joint-impedance gains
  (stiffness :data:`ARM_KP`, damping :data:`ARM_KV`) within the real torque limits, so the arm
  tracks joint targets at DROID speeds (use the ``implicitfast`` integrator);
* a ``tcp`` site sits between the finger pads (+z approach, +y finger axis).

Move groups: ``arm`` (7 joint positions, rad) and ``gripper`` (1 value, 0 open … 1 closed).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cache
from pathlib import Path
from typing import ClassVar

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.assets.builtin import PANDA_HAND
from molmo_lerobot.paths import package_asset_dir
from molmo_lerobot.robots.base import ArmGripperHandle, RobotType, add_mount
from molmo_lerobot.sim.spec_compat import set_joint_damping

PREFIX = "robot/"
#: finger joint travel (each finger, metres)
FINGER_TRAVEL = 0.04
#: TCP offset along link 7's z axis: finger base (0.1654) + middle of the finger pads (0.06)
TCP_OFFSET = 0.2254
#: standard Panda limits for the joints whose zero the kitchen model shifts
_STANDARD_LIMITS = {6: (-0.0175, 3.7525), 7: (-2.8973, 2.8973)}
#: joint-impedance position gains per arm joint (N·m/rad, N·m·s/rad)
ARM_KP = (4500.0, 4500.0, 3500.0, 3500.0, 2000.0, 2000.0, 2000.0)
ARM_KV = (450.0, 450.0, 350.0, 350.0, 200.0, 200.0, 200.0)


def franka_asset_dir() -> Path:
    """Directory of the Franka MJCF files inside the installed gymnasium-robotics package."""
    return package_asset_dir("gymnasium_robotics", "envs", "assets", "kitchen_franka", "franka_assets",
                             marker="chain.xml", what="the Franka robot")


@cache
def _base_xml() -> tuple[str, str]:
    root = franka_asset_dir()
    xml = (
        '<mujoco model="franka_panda">'
        f'<include file="{root / "assets.xml"}"/>'
        f'<worldbody><include file="{root / "chain.xml"}"/></worldbody>'
        f'<include file="{root / "actuator.xml"}"/>'
        "</mujoco>"
    )
    return xml, str(root)


def load_franka_spec() -> mujoco.MjSpec:
    """The adjusted Panda spec (see the module docstring), base at the origin."""
    xml, root = _base_xml()
    spec = mujoco.MjSpec.from_string(xml)
    # The include files name meshes relative to their meshdir; make every path absolute.
    meshdir = Path(root) / "meshes"
    for mesh in spec.meshes:
        mesh.file = str(meshdir / Path(mesh.file).relative_to(root))
    spec.meshdir = ""
    spec.nuser_actuator = -1
    for act in spec.actuators:
        act.userdata = []
    renames = {f"robot:panda0_joint{k}": (f"joint{k}", f"actuator{k}") for k in range(1, 8)}
    renames["robot:panda0_finger_joint1"] = ("finger_joint1", "finger_actuator1")
    renames["robot:panda0_finger_joint2"] = ("finger_joint2", "finger_actuator2")
    for act in spec.actuators:  # actuators name their joint: rename both together
        joint, actuator = renames[act.target]
        spec.joint(act.target).name = joint
        act.target, act.name = joint, actuator
    # Standard Panda joint zeros: link6/link7 frames are Rx(90°) like the real kinematics.
    for link in ("panda0_link6", "panda0_link7"):
        body = spec.body(link)
        body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        body.quat = [math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0]
    for k, (lo, hi) in _STANDARD_LIMITS.items():
        spec.joint(f"joint{k}").range = [lo, hi]
    for k in range(1, 8):  # position targets limited to the joint range
        joint, act = spec.joint(f"joint{k}"), spec.actuator(f"actuator{k}")
        act.ctrlrange = list(joint.range)
        kp, kv = ARM_KP[k - 1], ARM_KV[k - 1]
        act.gainprm = [kp] + [0.0] * 9
        act.biasprm = [0.0, -kp, -kv] + [0.0] * 7
        set_joint_damping(joint, 1.0)
        joint.armature = 0.1
    for body in spec.bodies:
        if body.name != "world":
            body.gravcomp = 1.0
    half = math.pi / 8  # TCP frame: link 7 rotated -45° about z, like the fingers
    spec.body("panda0_link7").add_site(
        name="tcp", pos=[0.0, 0.0, TCP_OFFSET], quat=[math.cos(half), 0.0, 0.0, -math.sin(half)], size=[0.005] * 3,
        group=4,
    )
    return spec


class FrankaHandle(ArmGripperHandle):
    """Move-group access to a compiled model holding the Franka under ``prefix``."""

    robot_name = "franka"

    def __init__(self, model: mujoco.MjModel, prefix: str) -> None:
        super().__init__(model, [f"{prefix}joint{k}" for k in range(1, 8)],
                         [f"{prefix}actuator{k}" for k in range(1, 8)], prefix + "tcp", prefix + "panda0_link0")
        fingers = [model.joint(prefix + name).id for name in ("finger_joint1", "finger_joint2")]
        self._fin_q = np.array([model.jnt_qposadr[j] for j in fingers])
        self._fin_v = np.array([model.jnt_dofadr[j] for j in fingers])
        self._fin_u = np.array([model.actuator(f"{prefix}finger_actuator{k}").id for k in (1, 2)])
        self._grip_q, self._grip_v = self._fin_q, self._fin_v

    def _gripper_qpos(self, data):
        return float(1.0 - data.qpos[self._fin_q].sum() / (2 * FINGER_TRAVEL))

    def _gripper_qvel(self, data):
        return float(-data.qvel[self._fin_v].sum() / (2 * FINGER_TRAVEL))

    def _gripper_set_qpos(self, data, closed):
        data.qpos[self._fin_q] = FINGER_TRAVEL * (1.0 - closed)
        data.qvel[self._fin_v] = 0.0

    def _gripper_target(self, data):
        return float(1.0 - data.ctrl[self._fin_u[0]] / FINGER_TRAVEL)

    def _gripper_command(self, data, closed):
        data.ctrl[self._fin_u] = FINGER_TRAVEL * (1.0 - closed)


class Franka(RobotType):
    """Franka Panda arm + hand (gymnasium-robotics meshes), joint-position controlled."""

    name = "franka"
    aliases = ("franka_panda",)  # never franka_droid: that is a Robotiq 2F-85, see franka_droid.py
    hand_geometry = PANDA_HAND
    move_groups: ClassVar[dict[str, int]] = {"arm": 7, "gripper": 1}
    joint_names: ClassVar[dict[str, list[str]]] = {"arm": [f"panda_joint{k}" for k in range(1, 8)],
                                                   "gripper": ["panda_gripper"]}
    #: hand pointing down above the table, fingers along the world y axis
    default_init_qpos: ClassVar[dict[str, list[float]]] = {"arm": [0.0, -0.55, 0.0, -2.4, 0.0, 1.85, 0.785],
                                                           "gripper": [0.0]}

    def init_qpos(self, group: str, values: Sequence[float]) -> np.ndarray:
        """Also accepts MolmoSpaces' two finger-joint positions (metres) for the gripper."""
        if group == "gripper" and len(values) == 2:
            return np.array([float(np.clip(1.0 - np.mean(values) / FINGER_TRAVEL, 0.0, 1.0))])
        return super().init_qpos(group, values)

    def spec(self) -> mujoco.MjSpec:
        return load_franka_spec()

    def add_to(self, world: mujoco.MjSpec, base_pose: Sequence[float],
               base_size: Sequence[float] | None = None) -> None:
        """No pedestal by default (the published ``*_v1`` benchmarks place the Panda's root at
        the base pose); with ``base_size``, MolmoSpaces' mount body ``robot/base`` and pedestal."""
        pose = self.base_pose(base_pose)
        if base_size is None:
            frame = world.worldbody.add_frame(pos=pose[:3], quat=pose[3:])
        else:
            frame = add_mount(world, PREFIX + "base", pose, base_size)
        frame.attach_body(load_franka_spec().body("panda0_link0"), PREFIX, "")

    def bind(self, model: mujoco.MjModel) -> FrankaHandle:
        return FrankaHandle(model, PREFIX)


@hookimpl
def molmo_robots() -> list[RobotType]:
    return [Franka()]
