"""A floating gripper (franka_droid's Robotiq 2F-85, or franka's Panda hand) that executes one grasp on
one object resting on a plane: pre-grasp 10 cm back along the approach → straight in → close → lift
15 cm → hold.

The gripper hangs from three slide joints (world x, y, z) under stiff position actuators, its
orientation fixed to the grasp's; physics options are the harness's (``sim.env.PHYSICS_OPTIONS``).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from molmo_lerobot.content.libero.grasps import GRIPPERS
from molmo_lerobot.robots.franka import FINGER_TRAVEL, TCP_OFFSET
from molmo_lerobot.robots.franka_droid import CTRL_CLOSED, TCP_DEPTH
from molmo_lerobot.sim.env import PHYSICS_OPTIONS
from molmo_lerobot.sim.scenes import attach_mjcf

DT = 0.002
PREGRASP = 0.10
LIFT = 0.15


def _site(angle: float, depth: float) -> np.ndarray:
    """The TCP site in the gripper's root body frame: turned ``angle`` about z, ``depth`` along it."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix()
    T[:3, 3] = [0.0, 0.0, depth]
    return T


#: robot -> (TCP site in the root body's frame, {actuator: (open, closed) ctrl}); franka_droid: pinch point,
#: fingers along its ±y; franka: link 7's tcp site between the pads (its wrist joint held at zero)
HANDS = {
    "franka_droid": (_site(-math.pi / 2, TCP_DEPTH), {"gripper/fingers_actuator": (0.0, CTRL_CLOSED)}),
    "franka": (_site(-math.pi / 4, TCP_OFFSET), {"finger_actuator1": (FINGER_TRAVEL, 0.0),
                                                 "finger_actuator2": (FINGER_TRAVEL, 0.0), "actuator7": (0.0, 0.0)}),
}


def lift_height(mjcf: str, uid: str, rest_z: float, grasp: np.ndarray, robot: str = "franka_droid") -> float:
    """How far (m) the object's centre rose after the lift, executing ``grasp`` (4x4, object frame) with
    ``robot``'s gripper."""
    site, actuators = HANDS[robot]
    world = mujoco.MjSpec()
    world.option.timestep = DT
    for k, v in PHYSICS_OPTIONS.items():
        setattr(world.option, k, v)
    world.worldbody.add_geom(name="table", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.1],
                             friction=[1.0, 0.01, 0.001])
    attach_mjcf(world, mjcf, uid, pos=[0.0, 0.0, rest_z])
    T_obj = np.eye(4)
    T_obj[2, 3] = rest_z
    T_tcp = T_obj @ grasp
    T_base = T_tcp @ np.linalg.inv(site)
    start = T_base[:3, 3] - PREGRASP * T_tcp[:3, 2]
    mover = world.worldbody.add_body(name="mover", pos=list(start), gravcomp=1.0)
    for k, axis in enumerate(np.eye(3)):
        mover.add_joint(name=f"slide{k}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=list(axis), damping=200.0)
        world.add_actuator(name=f"slide{k}", target=f"slide{k}", trntype=mujoco.mjtTrn.mjTRN_JOINT,
                           gaintype=mujoco.mjtGain.mjGAIN_FIXED, biastype=mujoco.mjtBias.mjBIAS_AFFINE,
                           gainprm=[5000.0] + [0.0] * 9, biasprm=[0.0, -5000.0, 0.0] + [0.0] * 7,
                           forcerange=[-200.0, 200.0])
    mover.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01], mass=1.0, contype=0, conaffinity=0)
    quat = Rotation.from_matrix(T_base[:3, :3]).as_quat(scalar_first=True)
    hand = mover.add_frame(quat=list(quat)).attach_body(GRIPPERS[robot].build()[0], "", "")
    hand.pos, hand.quat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]  # it sat on the arm's flange
    model = world.compile()
    data = mujoco.MjData(model)
    obj = model.body(uid).id
    grip = [model.actuator(name).id for name in actuators]
    ctrl = np.array(list(actuators.values()))  # (open, closed) per actuator
    mujoco.mj_forward(model, data)
    z0 = float(data.xpos[obj][2])
    approach = T_tcp[:3, 2]

    def run(seconds: float, target_from: np.ndarray, target_to: np.ndarray, gripper: float) -> None:
        n = int(seconds / DT)
        for i in range(n):
            s = (i + 1) / n
            data.ctrl[:3] = target_from + s * (target_to - target_from)
            data.ctrl[grip] = ctrl[:, 0] + gripper * (ctrl[:, 1] - ctrl[:, 0])
            mujoco.mj_step(model, data)

    zero = np.zeros(3)
    down = PREGRASP * approach
    up = down + np.array([0.0, 0.0, LIFT])
    run(0.3, zero, zero, 0.0)
    run(1.0, zero, down, 0.0)
    run(0.2, down, down, 0.0)
    run(0.8, down, down, 1.0)
    run(1.5, down, up, 1.0)
    run(0.5, up, up, 1.0)
    return float(data.xpos[obj][2]) - z0
