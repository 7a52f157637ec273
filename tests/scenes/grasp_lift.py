"""A floating Robotiq 2F-85 (franka_droid's gripper) that executes one grasp on one object resting on a
plane: pre-grasp 10 cm back along the approach → straight in → close → lift 15 cm → hold.

The gripper hangs from three slide joints (world x, y, z) under stiff position actuators, its
orientation fixed to the grasp's; physics options are the harness's (``sim.env.PHYSICS_OPTIONS``).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from molmo_lerobot.robots.franka_droid import CTRL_CLOSED, TCP_DEPTH, load_droid_spec
from molmo_lerobot.sim.env import PHYSICS_OPTIONS
from molmo_lerobot.sim.scenes import attach_mjcf

DT = 0.002
PREGRASP = 0.10
LIFT = 0.15
#: the TCP site in gripper/base's frame (franka_droid: pinch point, fingers along its ±y)
_SITE = np.eye(4)
_SITE[:3, :3] = Rotation.from_quat([math.cos(math.pi / 4), 0, 0, -math.sin(math.pi / 4)], scalar_first=True).as_matrix()
_SITE[:3, 3] = [0.0, 0.0, TCP_DEPTH]


def lift_height(mjcf: str, uid: str, rest_z: float, grasp: np.ndarray) -> float:
    """How far (m) the object's centre rose after the lift, executing ``grasp`` (4x4, object frame)."""
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
    T_base = T_tcp @ np.linalg.inv(_SITE)
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
    hand = mover.add_frame(quat=list(quat)).attach_body(load_droid_spec().body("gripper/base"), "", "")
    hand.pos, hand.quat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]  # it sat on the arm's flange
    model = world.compile()
    data = mujoco.MjData(model)
    obj = model.body(uid).id
    grip = model.actuator("gripper/fingers_actuator").id
    mujoco.mj_forward(model, data)
    z0 = float(data.xpos[obj][2])
    approach = T_tcp[:3, 2]

    def run(seconds: float, target_from: np.ndarray, target_to: np.ndarray, gripper: float) -> None:
        n = int(seconds / DT)
        for i in range(n):
            s = (i + 1) / n
            data.ctrl[:3] = target_from + s * (target_to - target_from)
            data.ctrl[grip] = gripper
            mujoco.mj_step(model, data)

    zero = np.zeros(3)
    down = PREGRASP * approach
    up = down + np.array([0.0, 0.0, LIFT])
    run(0.3, zero, zero, 0.0)
    run(1.0, zero, down, 0.0)
    run(0.2, down, down, 0.0)
    run(0.8, down, down, CTRL_CLOSED)
    run(1.5, down, up, CTRL_CLOSED)
    run(0.5, up, up, CTRL_CLOSED)
    return float(data.xpos[obj][2]) - z0
