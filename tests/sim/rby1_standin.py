"""A stand-in for MolmoSpaces' gated RB-Y1 model, written with MjSpec in their assets layout.

It has the names their ``RBY1RobotView`` (holonomic base) and ``RBY1MjcfCameraSystem`` look up,
already under the namespace ``robot_0/`` as in their file: root body ``base`` (slides
``base_x`` / ``base_y``, hinge ``base_theta``, site ``base_site``, wheels ``left_wheel`` /
``right_wheel``) inside a wrapper body 5 mm up; torso ``link_torso_0..5`` (joints
``torso_0..5``, actuators ``link1_act..link6_act``); head ``link_head_1`` / ``link_head_2``
(``head_0`` / ``head_1``, ``head_<i>_act``, camera ``head_camera``); arms ``link_<side>_arm_0..6``
(``<side>_arm_0..6``, ``<side>_arm_<i+1>_act``) ending in ``EE_BODY_L`` / ``EE_BODY_R`` with
sites ``ee_site_l`` / ``ee_site_r``, cameras ``wrist_camera_l`` / ``_r`` and slide fingers
``gripper_finger_<l|r>1/2`` coupled 2 = -1, one actuator ``<side>_finger_act`` (-0.05 open … 0
closed); a ``camera_follower`` behind the base and the two mocap markers their loader drops.
Dimensions are rough (a 1.4 m robot); nothing here is their geometry.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

NS = "robot_0/"
FILES = {"rby1": "rby1_site_control.xml", "rby1m": "rby1_v1.2_site_control.xml"}
#: torso joint axes and link offsets (m) in the parent link
TORSO = [((0, 0, 1), (0, 0, 0.25)), ((0, 1, 0), (0, 0, 0.1)), ((0, 1, 0), (0, 0, 0.3)),
         ((0, 1, 0), (0, 0, 0.3)), ((1, 0, 0), (0, 0, 0.1)), ((0, 0, 1), (0, 0, 0.05))]
ARM_AXES = [(0, 1, 0), (1, 0, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1)]


def _look_quat(forward, up=(0.0, 0.0, 1.0)) -> list[float]:
    """A MuJoCo camera (looks along -z, +y up) looking along ``forward``."""
    f = np.asarray(forward, dtype=float) / np.linalg.norm(forward)
    right = np.cross(f, up)
    right /= np.linalg.norm(right)
    mat = np.column_stack([right, np.cross(right, f), -f])
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, mat.flatten())
    return quat.tolist()


def _visual(body: mujoco.MjsBody, size: float, length: float) -> None:
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[size, 0, 0], fromto=[0, 0, 0, 0, 0, length],
                  contype=0, conaffinity=0, density=500.0, rgba=[0.8, 0.8, 0.85, 1])


def _position(spec: mujoco.MjSpec, name: str, joint: str, kp: float, lo: float, hi: float) -> None:
    spec.add_actuator(name=NS + name, target=NS + joint, trntype=mujoco.mjtTrn.mjTRN_JOINT,
                      gaintype=mujoco.mjtGain.mjGAIN_FIXED, biastype=mujoco.mjtBias.mjBIAS_AFFINE,
                      gainprm=[kp] + [0.0] * 9, biasprm=[0.0, -kp, 0.0] + [0.0] * 7, ctrlrange=[lo, hi])


def _arm(spec: mujoco.MjSpec, parent: mujoco.MjsBody, side: str) -> None:
    s = side[0]
    body = parent.add_body(name=f"{NS}link_{side}_arm_0", pos=[0, 0.22 if side == "left" else -0.22, 0])
    for i, axis in enumerate(ARM_AXES):
        if i:
            body = body.add_body(name=f"{NS}link_{side}_arm_{i}", pos=[0, 0, -0.14])
        body.add_joint(name=f"{NS}{side}_arm_{i}", axis=list(axis), range=[-3.0, 3.0], damping=2.0, armature=0.05)
        _visual(body, 0.04, -0.14)
        _position(spec, f"{side}_arm_{i + 1}_act", f"{side}_arm_{i}", 300.0, -3.0, 3.0)
    ee = body.add_body(name=f"{NS}EE_BODY_{s.upper()}", pos=[0, 0, -0.16])
    ee.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.03, 0.06, 0.02], density=500.0)
    ee.add_site(name=f"{NS}ee_site_{s}", pos=[0, 0, -0.1])
    ee.add_camera(name=f"{NS}wrist_camera_{s}", pos=[0.06, 0, 0], quat=_look_quat((0, 0, -1), (1, 0, 0)), fovy=58.0)
    for k, sign in ((1, 1.0), (2, -1.0)):
        finger = ee.add_body(name=f"{NS}{side}_finger_{k}", pos=[0, 0, -0.06])
        finger.add_joint(name=f"{NS}gripper_finger_{s}{k}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 1, 0],
                         range=[-0.05, 0.0] if sign > 0 else [0.0, 0.05], damping=5.0, armature=0.01)
        finger.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.01, 0.005, 0.04], pos=[0, -0.012 * sign, 0],
                        density=800.0, friction=[1.5, 0.01, 0.001])
    _position(spec, f"{side}_finger_act", f"gripper_finger_{s}1", 400.0, -0.05, 0.0)
    spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1=f"{NS}gripper_finger_{s}2", name2=f"{NS}gripper_finger_{s}1",
                      data=[0.0, -1.0, 0, 0, 0] + [0.0] * 6)


def standin_spec() -> mujoco.MjSpec:
    spec = mujoco.MjSpec()
    spec.compiler.degree = False
    wrapper = spec.worldbody.add_body(name=NS + "rby1", pos=[0, 0, 0.005])
    base = wrapper.add_body(name=NS + "base")
    base.add_joint(name=NS + "base_x", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
    base.add_joint(name=NS + "base_y", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 1, 0])
    base.add_joint(name=NS + "base_theta", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
    base.add_site(name=NS + "base_site")
    base.add_geom(name=NS + "base_box", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.3, 0.25, 0.1], pos=[0, 0, 0.18],
                  mass=40.0)
    base.add_camera(name=NS + "camera_follower", pos=[-1.5, 0, 1.6], quat=_look_quat((1.5, 0, -0.8)), fovy=60.0)
    for side, y in (("left", 0.27), ("right", -0.27)):
        wheel = base.add_body(name=f"{NS}{side}_wheel_link", pos=[0, y, 0.08])
        wheel.add_joint(name=f"{NS}{side}_wheel", axis=[0, 1, 0])
        wheel.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.08, 0.02, 0], quat=[0.7071068, 0.7071068, 0, 0],
                       mass=2.0)
    body = base
    for i, (axis, pos) in enumerate(TORSO):
        body = body.add_body(name=f"{NS}link_torso_{i}", pos=list(pos))
        body.add_joint(name=f"{NS}torso_{i}", axis=list(axis), range=[-1.5, 1.5], damping=20.0, armature=0.1)
        _visual(body, 0.1, TORSO[i + 1][1][2] if i + 1 < len(TORSO) else 0.05)
        _position(spec, f"link{i + 1}_act", f"torso_{i}", 3000.0, -1.5, 1.5)
    head = body.add_body(name=NS + "link_head_0", pos=[0, 0, 0.15])
    for i, axis in enumerate(((0, 0, 1), (0, 1, 0))):
        head = head.add_body(name=f"{NS}link_head_{i + 1}", pos=[0, 0, 0.05])
        head.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.04, 0, 0], contype=0, conaffinity=0, density=500.0)
        head.add_joint(name=f"{NS}head_{i}", axis=list(axis), range=[-1.0, 1.0], damping=1.0, armature=0.01)
        _position(spec, f"head_{i}_act", f"head_{i}", 50.0, -1.0, 1.0)
    head.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.06, 0.1, 0.06], contype=0, conaffinity=0, density=300.0)
    head.add_camera(name=NS + "head_camera", pos=[0.07, 0, 0], quat=_look_quat((1, 0, 0)), fovy=90.0)
    for side in ("left", "right"):
        _arm(spec, body, side)
    for side in ("left", "right"):
        marker = spec.worldbody.add_body(name=f"{NS}target_ee_pose_{side}", mocap=True)
        marker.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0], contype=0, conaffinity=0)
    return spec


def write_standin(assets_dir: Path, name: str = "rby1") -> Path:
    """The stand-in at ``<assets_dir>/robots/<name>/<their file name>``; returns its path."""
    path = Path(assets_dir) / "robots" / name / FILES[name]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(standin_spec().to_xml())
    return path
