"""``franka_droid``: a Franka arm with a Robotiq 2F-85 gripper, DROID's set-up, named as in MolmoSpaces.

Where MolmoSpaces' assets dir (:func:`molmo_lerobot.paths.molmospaces_assets_dir`) holds their
robot (``robots/franka_droid/model.xml``), that model is used as their ``FrankaRobot`` uses it:
its ``fr3_link0`` subtree, with gravity compensation on every body (their
``FrankaRobotConfig.gravcomp``). Otherwise the robot is built at run time from registry
packages (nothing is copied into this repository): the arm of
:mod:`molmo_lerobot.robots.franka` (gymnasium-robotics' Panda meshes, standard joint zeros,
joint-impedance gains) without its hand, with the FR3's published joint ranges, damping,
armature and friction (:data:`FR3_JOINTS`; the FR3 and the Panda share their kinematics), and
robosuite's ``robotiq_gripper_85.xml`` with its meshes, found through the installed package's
path (robosuite is never imported). ``docs/parity.md`` ("Robot") lists what still differs.

``franka_droid_fr3`` (:class:`FrankaDroidFR3`, a new robot version: benchmarks made for
``franka_droid`` keep their arm) builds the arm instead from franky-sim's FR3 (MuJoCo Menagerie's
``franka_fr3``: its link masses, inertias, meshes, joint ranges, damping, armature, friction and
gains, read from the installed package), with the same Robotiq, wrist mount, TCP and camera.

Either way the robot stands as MolmoSpaces' ``add_robot_to_scene`` places it: a mount body
``robot_0/base`` at ``task.robot_base_pose``, a box pedestal of ``base_size`` on it (their
``FrankaRobotConfig.base_size``, :data:`BASE_SIZE`, unless the episode or run overrides it), and
``fr3_link0`` on the pedestal's top.

Both share MolmoSpaces' names under the namespace ``robot_0/``, so their camera specs and
robot views resolve: bodies ``base`` (the mount), ``fr3_link0`` … and ``gripper/base``; arm
joints and actuators ``fr3_joint1..7``; gripper driver joints ``gripper/left_driver_joint`` /
``gripper/right_driver_joint`` (radians, 0 open … 0.8 closed) driven by one actuator
``gripper/fingers_actuator`` (0 open … 255 closed); the TCP site ``gripper/grasp_site`` and the
wrist camera ``gripper/wrist_camera``.

The TCP site follows MolmoSpaces' unified gripper convention (+z approach, fingers opening
along ±y, origin at the gripping centre between the pads), like the Panda's ``tcp`` site: it is
the Robotiq's pinch point, where the pad centres meet when the fingers close (MolmoSpaces'
Robotiq grasp generator puts its TCP there, 0.155 m from the coupling face). So an object-frame
grasp (``transforms`` of their grasp files) centres the pads on the same point of the object
on either hand.

Move groups: ``arm`` (7 joint positions, rad) and ``gripper`` (1 value, 0 open … 1 closed,
mapped linearly onto the actuator's 0 … 255). ``init_qpos["gripper"]`` takes MolmoSpaces' two
driver-joint angles in radians (``[0.00296, 0.00296]`` = open), set on those two joints alone as their
robot view sets them, or one normalized value, which sets the whole finger linkage.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cache
from pathlib import Path
from typing import ClassVar
from xml.etree import ElementTree

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.assets.builtin import ROBOTIQ_2F85
from molmo_lerobot.paths import molmospaces_assets_dir, package_asset_dir
from molmo_lerobot.robots.base import ArmGripperHandle, RobotHandle, RobotType, add_mount
from molmo_lerobot.robots.franka import load_franka_spec
from molmo_lerobot.sim.spec_compat import equality_data, set_joint_damping

NAMESPACE = "robot_0/"
#: MolmoSpaces' ``FrankaRobotConfig.base_size``: the pedestal under the arm (x, y, z metres)
BASE_SIZE = (0.5, 0.5, 0.58)
#: the FR3's joints: ranges as in mujoco_menagerie's franka_fr3_v2 (fr3v2.xml; its franka_fr3, which
#: MolmoSpaces' licence notes name, is narrower on joints 1, 2, 4-7: docs/parity.md, "Fallback arm vs FR3"):
#: range (rad), armature (kg·m²), friction loss (N·m); damping :data:`FR3_DAMPING` on all
FR3_JOINTS = (((-2.9007, 2.9007), 0.195, 1.137), ((-1.8361, 1.8361), 0.195, 1.137),
              ((-2.9007, 2.9007), 0.195, 1.137), ((-3.0770, -0.1169), 0.195, 1.137),
              ((-2.8763, 2.8763), 0.074, 0.763), ((0.4398, 4.6216), 0.074, 0.44),
              ((-3.0508, 3.0508), 0.074, 0.248))
FR3_DAMPING = 0.21
#: driver joint travel (rad): 0 open … DRIVER_CLOSED closed
DRIVER_CLOSED = 0.8
#: MolmoSpaces' gripper actuator range (0 open … 255 closed)
CTRL_CLOSED = 255.0
#: flange of link 7 (where the Panda hand sits), metres along its z axis
FLANGE = 0.107
#: TCP along the approach axis from ``gripper/base``: the pads' centre with the fingers closed (open,
#: the pads sit 1.4 cm behind it and swing forward as they close); see assets.builtin.ROBOTIQ_2F85
TCP_DEPTH = 0.144
#: gripper position gain (N·m per rad of driver angle on the coupled tendon) and damping; force limit
GRIPPER_KP, GRIPPER_KV, GRIPPER_FORCE = 100.0, 5.0, 10.0
#: wrist camera (ZED mini on DROID's mount) in the ``gripper/base`` frame: beside the gripper, looking along it
WRIST_CAMERA_POS = (0.0, 0.078, 0.023)
WRIST_CAMERA_QUAT = (0.0, 0.0, 0.9887, 0.1498)
WRIST_CAMERA_FOVY = 52.0
#: the gripper's finger chain: joints that follow the driver (+1) or mirror it (-1)
_FOLLOWERS = {"left_inner_knuckle_joint": ("finger_joint", 1.0),
              "left_inner_finger_joint": ("finger_joint", -1.0),
              "right_inner_knuckle_joint": ("right_outer_knuckle_joint", 1.0),
              "right_inner_finger_joint": ("right_outer_knuckle_joint", -1.0)}
_DRIVERS = {"finger_joint": "left_driver_joint", "right_outer_knuckle_joint": "right_driver_joint"}


def robotiq_xml() -> Path:
    """robosuite's Robotiq 2F-85 MJCF inside the installed package (the package is not imported)."""
    grippers = package_asset_dir("robosuite", "models", "assets", "grippers", marker="robotiq_gripper_85.xml",
                                 what="the franka_droid robot (Robotiq 2F-85 gripper)",
                                 install="pip install --no-deps robosuite: only its asset files are used")
    return grippers / "robotiq_gripper_85.xml"


def molmospaces_model(assets_dir: Path | None = None) -> Path | None:
    """MolmoSpaces' own ``franka_droid`` model in their assets dir, if installed."""
    path = (assets_dir or molmospaces_assets_dir()) / "robots" / "franka_droid" / "model.xml"
    return path if path.is_file() else None


def _robotiq_spec() -> mujoco.MjSpec:
    """robosuite's gripper with MolmoSpaces' names, a rigid finger linkage and one actuator."""
    path = robotiq_xml()
    root = ElementTree.parse(path).getroot()
    root.insert(0, ElementTree.Element("compiler", angle="radian"))  # robosuite's top-level model says so
    asset = root.find("asset")
    if asset is None:
        raise ValueError(f"{path}: no <asset> element")
    seen: set[str | None] = set()
    for mesh in list(asset.iter("mesh")):  # absolute paths; drop the repeated base mesh (its file is absent)
        mesh.set("file", str(path.parent / mesh.attrib["file"]))
        if mesh.get("name") in seen:
            asset.remove(mesh)
        seen.add(mesh.get("name"))
    spec = mujoco.MjSpec.from_string(ElementTree.tostring(root, encoding="unicode"))
    for sensor in list(spec.sensors):
        spec.delete(sensor)
    for tendon in list(spec.tendons):
        spec.delete(tendon)
    for act in list(spec.actuators):
        spec.delete(act)
    for site in list(spec.sites):
        spec.delete(site)
    spec.delete(spec.body("eef"))
    for geom in spec.geoms:  # robosuite's collision meshes are group 0: keep them out of camera images
        if geom.contype or geom.conaffinity:
            geom.group = 3
    for old, new in _DRIVERS.items():
        spec.joint(old).name = new
    for follower, (driver, coef) in _FOLLOWERS.items():
        spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1=follower, name2=_DRIVERS[driver],
                          data=equality_data(0.0, coef), solref=[0.005, 1.0])
    spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1="right_driver_joint", name2="left_driver_joint",
                      data=equality_data(0.0, 1.0), solref=[0.005, 1.0])
    for joint in spec.joints:
        joint.armature = 0.005
        set_joint_damping(joint, 0.1)
    split = spec.add_tendon(name="split")
    split.wrap_joint("left_driver_joint", 0.5)
    split.wrap_joint("right_driver_joint", 0.5)
    gain = GRIPPER_KP * DRIVER_CLOSED / CTRL_CLOSED
    spec.add_actuator(name="fingers_actuator", target="split", trntype=mujoco.mjtTrn.mjTRN_TENDON,
                      gaintype=mujoco.mjtGain.mjGAIN_FIXED, biastype=mujoco.mjtBias.mjBIAS_AFFINE,
                      gainprm=[gain] + [0.0] * 9, biasprm=[0.0, -GRIPPER_KP, -GRIPPER_KV] + [0.0] * 7,
                      ctrlrange=[0.0, CTRL_CLOSED], forcerange=[-GRIPPER_FORCE, GRIPPER_FORCE])
    return spec


def fr3_xml() -> Path:
    """franky-sim's FR3 MJCF (Menagerie's ``franka_fr3`` with its meshes) inside the installed package."""
    assets = package_asset_dir("franky_sim", "assets", marker="fr3.xml",
                               what="the franka_droid_fr3 robot (FR3 arm)",
                               install="pip install --no-deps franky-sim: only its asset files are used")
    return assets / "fr3.xml"


def _panda_arm() -> mujoco.MjSpec:
    """gymnasium-robotics' Panda without its hand, named and set up as the FR3 (:data:`FR3_JOINTS`)."""
    arm = load_franka_spec()
    for k in (1, 2):
        arm.delete(arm.actuator(f"finger_actuator{k}"))
    link7 = arm.body("panda0_link7")
    for child in list(link7.bodies):
        arm.delete(child)
    for geom in list(link7.geoms):
        if geom.meshname.startswith("hand"):
            arm.delete(geom)
    for site in list(link7.sites):
        arm.delete(site)
    for k, (limits, armature, friction) in enumerate(FR3_JOINTS, start=1):
        arm.body(f"panda0_link{k}").name = f"fr3_link{k}"
        joint = arm.joint(f"joint{k}")
        joint.name = f"fr3_joint{k}"
        joint.range, joint.armature, joint.frictionloss = list(limits), armature, friction
        set_joint_damping(joint, FR3_DAMPING)
        act = arm.actuator(f"actuator{k}")
        act.name = act.target = f"fr3_joint{k}"
        act.ctrlrange = list(limits)
    arm.body("panda0_link0").name = "fr3_link0"
    return arm


def _child(parent: ElementTree.Element, match: str, path: Path) -> ElementTree.Element:
    found = parent.find(match)
    if found is None:
        raise ValueError(f"{path}: no {match} under <{parent.tag}> (not franky-sim's FR3 layout)")
    return found


def _fr3_arm() -> mujoco.MjSpec:
    """franky-sim's FR3 as it ships (links, masses, inertias, meshes, joints, actuators) without its
    Franka Hand, ``fr3_link0`` at the origin (its file's top body dropped)."""
    path = fr3_xml()
    root = ElementTree.parse(path).getroot()
    worldbody, actuators, asset = (_child(root, tag, path) for tag in ("worldbody", "actuator", "asset"))
    top = _child(worldbody, "body", path)
    link0 = _child(top, "body[@name='fr3_link0']", path)
    link7 = _child(link0, ".//body[@name='fr3_link7']", path)
    hand = _child(link7, "body[@name='hand']", path)
    link0.set("childclass", top.get("childclass", "fr3"))
    worldbody.remove(top)
    worldbody.append(link0)
    link7.remove(hand)  # the Franka Hand, its fingers' tendon, equality, actuator and keyframe
    for tag in ("tendon", "equality", "keyframe"):
        for element in root.findall(tag):
            root.remove(element)
    for act in actuators.findall("general[@name='hand']"):
        actuators.remove(act)
    for mesh in asset.findall("mesh"):
        if mesh.get("name", "").startswith(("hand", "finger")):
            asset.remove(mesh)
        else:
            mesh.set("file", str(path.parent / "meshes" / mesh.attrib["file"]))
    for compiler in root.findall("compiler"):
        compiler.attrib.pop("meshdir", None)
    return mujoco.MjSpec.from_string(ElementTree.tostring(root, encoding="unicode"))


#: the arms franka_droid can be built with: ``panda`` (the published robot), ``fr3`` (franka_droid_fr3)
ARMS = {"panda": _panda_arm, "fr3": _fr3_arm}


@cache
def _registry_xml(arm_name: str = "panda") -> str:
    """The registry-built robot (arm :data:`ARMS` ``[arm_name]`` + robosuite's Robotiq) as MJCF text
    (absolute mesh paths), ``fr3_link0`` at the origin."""
    arm = ARMS[arm_name]()
    # link 7's frame is the standard one (see franka.py); the gripper at the flange, fingers
    # along link 7's ±y rotated by the DROID mount so that q7 = 0 aligns them with the base
    base = arm.body("fr3_link7").add_body(name="gripper/base", pos=[0.0, 0.0, FLANGE], mass=0.01,
                                         inertia=[1e-5] * 3)
    # robosuite's fingers open along its adapter's y; MolmoSpaces' gripper/base has them along x
    # (their wrist camera sits at +y and sees the fingers close left-right)
    quarter = [math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]
    base.add_frame(quat=quarter).attach_body(_robotiq_spec().body("robotiq_85_adapter_link"), "gripper/", "")
    # the TCP: fingers along its ±y (MolmoSpaces' unified convention), +z approach
    base.add_site(name="gripper/grasp_site", pos=[0.0, 0.0, TCP_DEPTH], size=[0.005] * 3, group=4,
                  quat=[math.cos(math.pi / 4), 0.0, 0.0, -math.sin(math.pi / 4)])
    base.add_camera(name="gripper/wrist_camera", pos=list(WRIST_CAMERA_POS), quat=list(WRIST_CAMERA_QUAT),
                    fovy=WRIST_CAMERA_FOVY)
    for body in arm.bodies:
        if body.name != "world":
            body.gravcomp = 1.0
    gripper_bodies = [b.name for b in arm.bodies if b.name.startswith("gripper/")]
    for i, a in enumerate(gripper_bodies):  # the linkage's links overlap by design
        for b in gripper_bodies[i + 1:]:
            arm.add_exclude(bodyname1=a, bodyname2=b)
    arm.add_exclude(bodyname1="fr3_link7", bodyname2="gripper/base")
    return arm.to_xml()


def load_droid_spec(assets_dir: Path | None = None, arm: str = "panda") -> mujoco.MjSpec:
    """The robot as a standalone spec at the origin, its arm's root body ``fr3_link0``:
    MolmoSpaces' model if installed (every body gravity-compensated, as their
    ``apply_control_overrides`` does), else the registry-built one with ``arm`` (:data:`ARMS`)."""
    theirs = molmospaces_model(assets_dir)
    if theirs is None:
        return mujoco.MjSpec.from_string(_registry_xml(arm))
    spec = mujoco.MjSpec.from_file(str(theirs))
    if spec.body("fr3_link0") is None:
        raise ValueError(f"{theirs}: no body 'fr3_link0' (MolmoSpaces' Franka root body)")
    for body in spec.body("fr3_link0").find_all("body"):
        body.gravcomp = 1.0
    return spec


class FrankaDroidHandle(ArmGripperHandle):
    """Move-group access to a compiled model holding ``franka_droid`` under ``prefix``."""

    robot_name = "franka_droid"

    def __init__(self, model: mujoco.MjModel, prefix: str = NAMESPACE) -> None:
        names = [f"{prefix}fr3_joint{k}" for k in range(1, 8)]  # joints and actuators share names
        super().__init__(model, names, names, f"{prefix}gripper/grasp_site", f"{prefix}base")
        drivers = [model.joint(f"{prefix}gripper/{s}_driver_joint").id for s in ("left", "right")]
        self._drv_q = np.array([model.jnt_qposadr[j] for j in drivers])
        self._drv_v = np.array([model.jnt_dofadr[j] for j in drivers])
        self._grip_q, self._grip_v = self._drv_q, self._drv_v
        self._grip_u = model.actuator(f"{prefix}gripper/fingers_actuator").id
        self._g_lo, self._g_hi = (float(v) for v in model.actuator_ctrlrange[self._grip_u])
        # every joint of the finger linkage follows the drivers: teleports set them too
        self._linkage = [(model.jnt_qposadr[j], model.jnt_dofadr[j], sign)
                         for name, (_, sign) in _FOLLOWERS.items()
                         if (j := mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"{prefix}gripper/{name}")) >= 0]

    def set_driver_angles(self, data: mujoco.MjData, angles: Sequence[float]) -> None:
        """Write the two driver joints alone (rad, at rest), as MolmoSpaces' ``RobotIQGripperGroup`` writes
        its ``joint_pos``: the finger linkage stays where it is until the joint equalities pull it along."""
        data.qpos[self._drv_q] = angles
        data.qvel[self._drv_v] = 0.0

    def _gripper_qpos(self, data):
        return float(np.clip(data.qpos[self._drv_q].mean() / DRIVER_CLOSED, 0.0, 1.0))

    def _gripper_qvel(self, data):
        return float(data.qvel[self._drv_v].mean() / DRIVER_CLOSED)

    def _gripper_set_qpos(self, data, closed):
        angle = DRIVER_CLOSED * closed
        data.qpos[self._drv_q] = angle
        data.qvel[self._drv_v] = 0.0
        for qadr, dadr, sign in self._linkage:
            data.qpos[qadr] = sign * angle
            data.qvel[dadr] = 0.0

    def _gripper_target(self, data):
        return float((data.ctrl[self._grip_u] - self._g_lo) / (self._g_hi - self._g_lo))

    def _gripper_command(self, data, closed):
        data.ctrl[self._grip_u] = self._g_lo + closed * (self._g_hi - self._g_lo)


class FrankaDroid(RobotType):
    """Franka arm + Robotiq 2F-85 (DROID), MolmoSpaces' names; see the module docstring."""

    name = "franka_droid"
    move_groups: ClassVar[dict[str, int]] = {"arm": 7, "gripper": 1}
    joint_names: ClassVar[dict[str, list[str]]] = {"arm": [f"fr3_joint{k}" for k in range(1, 8)],
                                                   "gripper": ["robotiq_gripper"]}
    default_camera_system = "FrankaDroidCameraSystem"
    default_base_size = BASE_SIZE
    hand_geometry = ROBOTIQ_2F85
    #: the registry-built arm (:data:`ARMS`) used where MolmoSpaces' model is not installed
    arm = "panda"
    #: MolmoSpaces' FrankaRobotConfig.init_qpos (gripper open)
    default_init_qpos: ClassVar[dict[str, list[float]]] = {"arm": [0.0, -0.7853, 0.0, -2.35619, 0.0, 1.57079, 0.0],
                                                           "gripper": [0.0]}

    def init_qpos(self, group: str, values: Sequence[float]) -> np.ndarray:
        """MolmoSpaces' gripper ``init_qpos`` is the two driver angles (rad); one value is normalized."""
        if group == "gripper" and len(values) == 2:
            lo, hi = min(values), max(values)
            if lo < -0.05 or hi > DRIVER_CLOSED + 0.05:
                raise ValueError(f"gripper driver angles {list(values)} outside [0, {DRIVER_CLOSED}] rad")
            return np.array([float(np.clip(np.mean(values) / DRIVER_CLOSED, 0.0, 1.0))])
        return super().init_qpos(group, values)

    def set_init_qpos(self, handle: RobotHandle, data: mujoco.MjData, group: str, values: Sequence[float]) -> None:
        """MolmoSpaces' two driver angles start the gripper as their robot view does: on the driver joints
        alone (:meth:`FrankaDroidHandle.set_driver_angles`), the linkage at the reset's rest position; one
        normalized value starts the whole linkage there."""
        if group == "gripper" and len(values) == 2 and isinstance(handle, FrankaDroidHandle):
            closed = self.init_qpos(group, values)  # checks the range
            handle.set_driver_angles(data, values)
            handle.command(data, group, closed)
        else:
            super().set_init_qpos(handle, data, group, values)

    def spec(self) -> mujoco.MjSpec:
        return load_droid_spec(arm=self.arm)

    def add_to(self, world: mujoco.MjSpec, base_pose: Sequence[float],
               base_size: Sequence[float] | None = None) -> None:
        """Mount body ``robot_0/base`` at ``base_pose``, pedestal ``base_size``, arm on top (their
        ``add_robot_to_scene``); :meth:`place` passes :data:`BASE_SIZE` unless overridden."""
        top = add_mount(world, NAMESPACE + "base", self.base_pose(base_pose), base_size)
        top.attach_body(load_droid_spec(arm=self.arm).body("fr3_link0"), NAMESPACE, "")

    def bind(self, model: mujoco.MjModel) -> FrankaDroidHandle:
        handle = FrankaDroidHandle(model, NAMESPACE)
        handle.robot_name = self.name
        return handle


class FrankaDroidFR3(FrankaDroid):
    """``franka_droid`` with the FR3 arm of franky-sim (Menagerie's ``franka_fr3``: its masses, inertias,
    meshes, joint ranges and gains) where MolmoSpaces' own model is not installed; a new robot version,
    so benchmarks made for ``franka_droid`` keep their arm (docs/parity.md, "The FR3 arm")."""

    name = "franka_droid_fr3"
    arm = "fr3"
    hand_of = "franka_droid"  # the same Robotiq at the same TCP: its grasps serve


@hookimpl
def molmo_robots() -> list[RobotType]:
    return [FrankaDroid(), FrankaDroidFR3()]
