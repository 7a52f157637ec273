"""mobile_franka against MolmoSpaces' own ``MobileFrankaRobot.add_robot_to_scene`` and config.

Both sides build the robot (their loader reads our franka_droid arm from a robot directory in their
layout, tests/parity/their_mobile_base.py) at several start poses; the base's box, joints,
actuators, the arm's root, the move groups and their order, and the base pose after a commanded
move (their base group's ``ctrl`` vs our ``command``) must agree.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from molmo_lerobot.robots.franka_droid import load_droid_spec
from molmo_lerobot.robots.mobile_franka import BASE_JOINTS, MobileFranka

pytestmark = pytest.mark.parity

DT, STEPS = 0.002, 750
CASES = [{"pose": [0.0, 0.0, 0.0], "target": [0.3, -0.2, 0.5]},
         {"pose": [2.5, -1.0, 1.2], "target": [2.8, -0.6, 2.0]},
         {"pose": [-3.0, 4.0, -2.8], "target": [-3.2, 4.1, 2.9]}]  # a yaw target across ±π


def _ours(case: dict) -> dict:
    world = mujoco.MjSpec()
    world.compiler.degree = False
    world.option.timestep = DT
    world.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    x, y, yaw = case["pose"]
    robot = MobileFranka()
    robot.add_to(world, [x, y, 0.005, math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)], robot.default_base_size)
    model = world.compile()
    data = mujoco.MjData(model)
    handle = robot.bind(model)
    mujoco.mj_forward(model, data)
    joints = {n: {"type": int(model.jnt_type[j]), "axis": model.jnt_axis[j].tolist(),
                  "range": model.jnt_range[j].tolist(),
                  "limited": bool(model.jnt_limited[j]), "qpos0": float(model.qpos0[model.jnt_qposadr[j]])}
              for n in BASE_JOINTS for j in [model.joint("robot_0/" + n).id]}
    acts = {n: {"trntype": int(model.actuator_trntype[a]), "gear": model.actuator_gear[a].tolist(),
                "ctrlrange": model.actuator_ctrlrange[a].tolist(), "limited": bool(model.actuator_ctrllimited[a]),
                "gain": float(model.actuator_gainprm[a][0]), "bias": model.actuator_biasprm[a][:3].tolist()}
            for n in BASE_JOINTS for a in [model.actuator(f"robot_0/{n}_act").id]}
    box = model.geom("robot_0/base/box").id
    start = handle.qpos(data, "base")
    for group in robot.move_groups:
        handle.set_qpos(data, group, handle.qpos(data, group) if group != "base" else np.zeros(0))
    handle.command(data, "base", np.asarray(case["target"]))
    mujoco.mj_step(model, data, nstep=STEPS)
    return {"groups": list(robot.move_groups), "joints": joints, "actuators": acts,
            "box": {"size": model.geom_size[box].tolist(), "pos": data.geom_xpos[box].tolist()},
            "arm_root": data.xpos[model.body("robot_0/fr3_link0").id].tolist(),
            "start": start.tolist(), "end": handle.qpos(data, "base").tolist()}


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_mobile_franka_matches_their_robot(theirs):
    got = theirs.run("their_mobile_base:build", {"xml": load_droid_spec().to_xml(), "cases": CASES,
                                                 "dt": DT, "steps": STEPS})["cases"]
    robot = MobileFranka()
    for case, their in zip(CASES, got, strict=True):
        ours = _ours(case)
        assert list(robot.default_base_size) == their["base_size"] == [0.5, 0.5, 0.58]
        assert their["command_mode"]["base"] == "holo_joint_planar_position"
        assert their["init_qpos"]["arm"] == robot.default_init_qpos["arm"]
        assert ours["groups"] == their["groups"] == ["base", "arm", "gripper"]
        for name in BASE_JOINTS:
            o, t = ours["joints"][name], their["joints"][name]
            assert o["type"] == t["type"] and o["limited"] == t["limited"], name
            assert np.allclose(o["axis"], t["axis"], atol=1e-12) and np.allclose(o["range"], t["range"]), name
            assert o["qpos0"] == pytest.approx(t["qpos0"], abs=1e-12), name
            oa, ta = ours["actuators"][name], their["actuators"][name]
            assert oa["trntype"] == ta["trntype"] and oa["limited"] == ta["limited"], name
            assert np.allclose(oa["gear"], ta["gear"]) and np.allclose(oa["ctrlrange"], ta["ctrlrange"]), name
            assert oa["gain"] == ta["gain"] and np.allclose(oa["bias"], ta["bias"], rtol=1e-9), name  # damping included
        assert np.allclose(ours["box"]["size"], their["box"]["size"])
        assert np.allclose(ours["box"]["pos"], their["box"]["pos"])
        assert np.allclose(ours["arm_root"], their["arm_root"], atol=1e-9)
        assert np.allclose(ours["start"], their["start"], atol=1e-9)
        assert np.allclose(ours["end"][:2], their["end"][:2], atol=1e-6)
        assert abs(_wrap(ours["end"][2] - their["end"][2])) < 1e-6
        assert np.allclose(ours["end"][:2], case["target"][:2], atol=1e-3)  # both got where commanded
