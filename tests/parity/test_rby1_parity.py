"""rby1 / rby1m against MolmoSpaces' own ``RBY1.add_robot_to_scene``, ``RBY1Config`` /
``RBY1MConfig`` and ``RBY1RobotView`` on the same stand-in model (tests/sim/rby1_standin.py, written
as their robot directory on their side, tests/parity/their_rby1.py): the file each config reads,
move groups with their joints and actuators in order, the base actuators, gravity compensation,
init_qpos, the start pose, and the base and gripper after the same commands must agree — also
where a yaw target crosses ±π and both bases spin (their yaw actuator: a site transmission whose
length wraps at ±π, ctrl range ±π).
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
from rby1_standin import FILES, standin_spec, write_standin

from molmo_lerobot.robots.rby1 import BASE_ACTUATORS, GROUPS, RBY1

pytestmark = pytest.mark.parity

DT, STEPS = 0.002, 1000
POSE = [1.5, -0.7, 2.6]
TARGETS = [[1.9, -0.4, 2.0], [1.9, -0.4, -2.9]]  # the second's yaw is across ±π


def _ours(name: str, assets: Path, target: list[float]) -> dict:
    robot = RBY1(name, FILES[name], str(assets))
    world = mujoco.MjSpec()
    world.compiler.degree = False
    world.option.timestep = DT
    world.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    x, y, yaw = POSE
    robot.add_to(world, [x, y, 0.0, math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    model = world.compile()
    data = mujoco.MjData(model)
    handle = robot.bind(model)
    for group, values in robot.default_init_qpos.items():
        handle.set_qpos(data, group, robot.init_qpos(group, values))
    mujoco.mj_forward(model, data)
    joint_pos = {g: handle.joint_qpos(data, g).tolist() for g in GROUPS}
    start_xpos = data.xpos[model.body("robot_0/base").id].tolist()
    handle.command(data, "left_gripper", np.array([1.0]))
    handle.command(data, "base", np.asarray(target))
    mujoco.mj_step(model, data, nstep=STEPS)
    acts = {}
    for n in BASE_ACTUATORS:
        a = model.actuator(f"robot_0/{n}_act").id
        acts[n] = {"trntype": int(model.actuator_trntype[a]), "gear": model.actuator_gear[a].tolist(),
                   "ctrlrange": model.actuator_ctrlrange[a].tolist(),
                   "site": model.site(int(model.actuator_trnid[a][0])).name,
                   "refsite": model.site(int(model.actuator_trnid[a][1])).name,
                   "gain": float(model.actuator_gainprm[a][0]), "bias": model.actuator_biasprm[a][:3].tolist()}
    return {"groups": {g: {"joints": [f"robot_0/{j}" for j in joints], "actuators": [f"robot_0/{a}" for a in acts_]}
                       for g, (joints, acts_) in GROUPS.items()},
            "actuators": acts, "gravcomp": {model.body(b).name: float(model.body_gravcomp[b])
                                            for b in range(1, model.nbody)},
            "joint_pos": joint_pos, "start_xpos": start_xpos,
            "end": {"base": handle.joint_qpos(data, "base").tolist(),
                    "left_gripper": handle.joint_qpos(data, "left_gripper").tolist()}}


def test_rby1_matches_their_robot(theirs, tmp_path):
    got = theirs.run("their_rby1:build", {"xml": standin_spec().to_xml(), "pose": POSE, "targets": TARGETS,
                                          "dt": DT, "steps": STEPS})
    for name in ("rby1", "rby1m"):
        write_standin(tmp_path, name)
        their, robot = got[name], RBY1(name, FILES[name])
        runs = [_ours(name, tmp_path, target) for target in TARGETS]
        ours = runs[0]
        assert their["xml"] == FILES[name]
        assert list(their["groups"]) == list(ours["groups"])  # base, torso, arms, grippers, head: their order
        assert their["groups"] == ours["groups"]
        assert list(robot.move_groups) == [g for g in their["groups"] if their["command_mode"].get(g, "") is not None]
        assert their["command_mode"]["base"] == "holo_joint_planar_position" and their["command_mode"]["head"] is None
        assert their["actuators"] == ours["actuators"]
        assert their["gravcomp"] == ours["gravcomp"]
        for group, values in their["init_qpos"].items():
            if group != "base":
                assert robot.default_init_qpos[group] == pytest.approx(values), group
        for group, values in their["joint_pos"].items():
            assert ours["joint_pos"][group] == pytest.approx(values, abs=1e-12), group
        assert ours["start_xpos"] == pytest.approx(their["start_xpos"], abs=1e-12)
        for target, mine, end in zip(TARGETS, runs, their["ends"], strict=True):
            assert mine["end"]["base"] == pytest.approx(end["base"], abs=1e-6), target
            assert mine["end"]["left_gripper"] == pytest.approx(end["left_gripper"], abs=1e-6), target
        assert runs[0]["end"]["base"] == pytest.approx(TARGETS[0], abs=1e-3)  # both got where commanded
        assert runs[0]["end"]["left_gripper"] == pytest.approx([0.0, 0.0], abs=2e-3)  # closed
        assert abs(runs[1]["end"]["base"][2]) > 10  # ... or both spin
