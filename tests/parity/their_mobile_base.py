"""MolmoSpaces' side of tests/parity/test_mobile_franka_parity.py: their ``MobileFrankaRobot.add_robot_to_scene``,
``MobileFrankaRobotConfig`` and ``MobileFrankaDroidRobotView``.

Their robot directory is gated, so it is made here in their layout: ``model.xml`` is our franka_droid
arm (the MJCF our side sends, meshes by absolute path; plus the two massless pad geoms their gripper
group looks up by name) and the base texture their code insists on.
Their module uses ``scipy``'s ``Rotation`` as ``R`` but imports it only under ``__main__``; the helper
binds that name before calling it. Runs in the parity venv: imports only their package, mujoco,
numpy, scipy and PIL.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import mujoco
import numpy as np

BASE_NAMES = ("base_x", "base_y", "base_theta")


def _robot_dir(root: Path, xml: str) -> None:
    spec = mujoco.MjSpec.from_string(xml)
    for side in ("left", "right"):  # their gripper group names its pads; ours has other geom names
        spec.body("gripper/base").add_geom(name=f"gripper/{side}_pad2", size=[0.001, 0, 0], contype=0,
                                           conaffinity=0, mass=0.0)
    (root / "model.xml").write_text(spec.to_xml())
    textures = root / "assets" / "base_textures"
    textures.mkdir(parents=True)
    from PIL import Image

    Image.new("RGB", (8, 8), (84, 61, 43)).save(textures / "DarkWood2.png")


def build(inputs: dict) -> dict:
    """For each case (x, y, yaw): their robot in an empty radian-unit world, its config values, the
    base's joints, actuators and box, the view's move groups and base pose, and the base pose after
    commanding ``target`` through their base group for ``steps`` physics steps."""
    import molmo_spaces.robots.mobile_franka as their_module
    from molmo_spaces.configs.robot_configs import MobileFrankaRobotConfig
    from molmo_spaces.robots.mobile_franka import MobileFrankaRobot
    from molmo_spaces.robots.robot_views.mobile_franka_droid_view import MobileFrankaDroidRobotView
    from scipy.spatial.transform import Rotation

    their_module.R = Rotation
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        _robot_dir(root, inputs["xml"])
        for case in inputs["cases"]:
            config = MobileFrankaRobotConfig(robot_dir=root)
            spec = mujoco.MjSpec()
            spec.compiler.degree = False
            spec.option.timestep = inputs["dt"]
            spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
            x, y, yaw = case["pose"]
            quat = Rotation.from_euler("z", yaw).as_quat(scalar_first=True).tolist()
            MobileFrankaRobot.add_robot_to_scene(config, spec, prefix=config.robot_namespace, pos=[x, y], quat=quat)
            MobileFrankaRobot.apply_control_overrides(spec, config)
            model = spec.compile()
            data = mujoco.MjData(model)
            mujoco.mj_forward(model, data)
            view = MobileFrankaDroidRobotView(data, config.robot_namespace)
            ns = config.robot_namespace
            joints = {n: {"type": int(model.jnt_type[j]), "axis": model.jnt_axis[j].tolist(),
                          "range": model.jnt_range[j].tolist(), "limited": bool(model.jnt_limited[j]),
                          "qpos0": float(model.qpos0[model.jnt_qposadr[j]])}
                      for n in BASE_NAMES for j in [model.joint(ns + n).id]}
            acts = {n: {"trntype": int(model.actuator_trntype[a]), "gear": model.actuator_gear[a].tolist(),
                        "ctrlrange": model.actuator_ctrlrange[a].tolist(),
                        "limited": bool(model.actuator_ctrllimited[a]),
                        "gain": float(model.actuator_gainprm[a][0]), "bias": model.actuator_biasprm[a][:3].tolist()}
                    for n in BASE_NAMES for a in [model.actuator(f"{ns}{n}_act").id]}
            base = model.body(ns + "base").id
            box = next(g for g in range(model.ngeom) if model.geom_bodyid[g] == base
                       and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX)
            start = view.base.pose.copy()
            for group in view.move_group_ids():  # hold every group where it is, then drive the base
                view.get_move_group(group).ctrl = view.get_move_group(group).noop_ctrl
            view.base.ctrl = np.asarray(case["target"], dtype=np.float64)
            mujoco.mj_step(model, data, nstep=inputs["steps"])
            end = view.base.pose
            out.append({"base_size": list(config.base_size), "command_mode": config.command_mode,
                        "init_qpos": {k: list(map(float, v)) for k, v in config.init_qpos.items()},
                        "groups": list(view.move_group_ids()), "joints": joints, "actuators": acts,
                        "box": {"size": model.geom_size[box].tolist(), "pos": data.geom_xpos[box].tolist()},
                        "arm_root": data.xpos[model.body(ns + "fr3_link0").id].tolist(),
                        "start": [float(start[0, 3]), float(start[1, 3]), float(np.arctan2(start[1, 0], start[0, 0]))],
                        "end": [float(end[0, 3]), float(end[1, 3]), float(np.arctan2(end[1, 0], end[0, 0]))]})
    return {"cases": out}
