"""MolmoSpaces' side of tests/parity/test_rby1_parity.py: their ``RBY1.add_robot_to_scene`` and
``apply_control_overrides`` under ``RBY1Config`` / ``RBY1MConfig``, and their ``RBY1RobotView``
(holonomic base), over the stand-in model our side sends (written as their robot directory).
Runs in the parity venv: imports only their package, mujoco, numpy and scipy.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import mujoco
import numpy as np


def build(inputs: dict) -> dict:
    """Per config: their view's groups (joint and actuator names in order), the base actuators,
    gravity compensation, init_qpos and command modes; then, per target, the base set to ``pose``
    (their ``set_world_pose`` on the base group), every group held, the left gripper closed and the
    base commanded to the target for ``steps`` physics steps."""
    from molmo_spaces.configs.robot_configs import RBY1Config, RBY1MConfig
    from molmo_spaces.robots.rby1 import RBY1
    from molmo_spaces.robots.robot_views.rby1_view import RBY1RobotView
    from scipy.spatial.transform import Rotation

    x, y, yaw = inputs["pose"]
    pose = np.eye(4)
    pose[:2, 3] = [x, y]
    pose[:3, :3] = Rotation.from_euler("z", yaw).as_matrix()
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for config_cls in (RBY1Config, RBY1MConfig):
            root = Path(tmp) / config_cls.__name__
            root.mkdir()
            config = config_cls(robot_dir=root)
            (root / config.robot_xml_path).write_text(inputs["xml"])
            spec = mujoco.MjSpec()
            spec.compiler.degree = False
            spec.option.timestep = inputs["dt"]
            spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
            RBY1.add_robot_to_scene(config, spec, prefix=config.robot_namespace, pos=[0.0, 0.0],
                                    quat=[1.0, 0.0, 0.0, 0.0])
            RBY1.apply_control_overrides(spec, config)
            model = spec.compile()
            data = mujoco.MjData(model)
            view = RBY1RobotView(data, config.robot_namespace, holo_base=config.use_holo_base)
            ends = [_drive(model, config, view, pose, target, inputs["steps"]) for target in inputs["targets"]]
            groups = {}
            for gid in view.move_group_ids():
                group = view.get_move_group(gid)
                groups[gid] = {"joints": [model.joint(int(j)).name for j in group._joint_ids],
                               "actuators": [model.actuator(int(a)).name for a in group._actuator_ids]}
            acts = {}
            for name in ("base_x", "base_y", "base_theta"):
                a = model.actuator(f"robot_0/{name}_act").id
                acts[name] = {"trntype": int(model.actuator_trntype[a]), "gear": model.actuator_gear[a].tolist(),
                              "ctrlrange": model.actuator_ctrlrange[a].tolist(),
                              "site": model.site(int(model.actuator_trnid[a][0])).name,
                              "refsite": model.site(int(model.actuator_trnid[a][1])).name,
                              "gain": float(model.actuator_gainprm[a][0]),
                              "bias": model.actuator_biasprm[a][:3].tolist()}
            out[config.name] = {
                "xml": str(config.robot_xml_path), "groups": groups, "actuators": acts,
                "gravcomp": {model.body(b).name: float(model.body_gravcomp[b]) for b in range(1, model.nbody)},
                "init_qpos": {k: np.asarray(v, dtype=float).tolist() for k, v in config.init_qpos.items()},
                "command_mode": dict(config.command_mode), **ends[0][0], "ends": [e for _, e in ends]}
    return out


def _drive(model, config, view, pose, target, steps) -> tuple[dict, dict]:
    """The start state after their reset at ``pose``, and the base and left gripper after the commands."""
    data = view.mj_data
    mujoco.mj_resetData(model, data)
    view.base.pose = pose
    for gid, values in config.init_qpos.items():
        if gid != "base":
            view.get_move_group(gid).joint_pos = np.asarray(values, dtype=np.float64)
    mujoco.mj_forward(model, data)
    start = {"joint_pos": {gid: view.get_move_group(gid).joint_pos.tolist() for gid in view.move_group_ids()},
             "start_xpos": data.xpos[model.body("robot_0/base").id].tolist()}
    for gid in view.move_group_ids():
        view.get_move_group(gid).ctrl = view.get_move_group(gid).noop_ctrl
    view.get_move_group("left_gripper").set_gripper_ctrl_open(False)
    view.base.ctrl = np.asarray(target, dtype=np.float64)
    mujoco.mj_step(model, data, nstep=steps)
    gripper = view.get_move_group("left_gripper")
    return start, {"base": view.base.joint_pos.tolist(), "left_gripper": gripper.joint_pos.tolist()}
