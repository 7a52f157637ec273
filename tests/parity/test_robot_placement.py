"""Robot placement against MolmoSpaces' own scene assembly (``FrankaRobot.add_robot_to_scene``).

Their code places a mount body at the base pose, a ``base_size`` pedestal on it and the arm's
root on top; ours must put every body, the pedestal and the TCP where theirs does, for several
base poses and pedestals (their default, a custom one, none). Only their gated robot model is
replaced: their loader reads our arm's kinematic tree from a robot directory in their layout
(tests/parity/their_placement.py), for both arms: ``franka_droid`` (the Panda-built one) and
``franka_droid_fr3`` (franky-sim's FR3).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from molmo_lerobot.robots.franka_droid import BASE_SIZE, FrankaDroid, FrankaDroidFR3, load_droid_spec

pytestmark = pytest.mark.parity

BODIES = ["robot_0/base", "robot_0/fr3_link0", "robot_0/fr3_link4", "robot_0/fr3_link7", "robot_0/gripper/base"]
TCP = "robot_0/gripper/grasp_site"
QPOS = [0.0, -0.7853, 0.0, -2.35619, 0.0, 1.57079, 0.0]  # their FrankaRobotConfig.init_qpos["arm"]


def _yaw(deg: float) -> list[float]:
    return [math.cos(math.radians(deg) / 2), 0.0, 0.0, math.sin(math.radians(deg) / 2)]


CASES = [{"pose": [0.0, 0.0, 0.0, *_yaw(0)], "base_size": list(BASE_SIZE)},
         {"pose": [1.61, 4.41, 0.07, 0.9, 0.0, 0.0, -0.45], "base_size": list(BASE_SIZE)},  # an iTHOR episode's
         {"pose": [-2.0, 0.5, 0.3, *_yaw(135)], "base_size": [0.4, 0.6, 0.75]},
         {"pose": [0.3, -1.2, 0.0, *_yaw(-60)], "base_size": None}]


ROBOTS = [FrankaDroid, FrankaDroidFR3]


def _tree(arm: str) -> list[dict]:
    """Our arm's kinematic tree (fr3_link0 down), as their side rebuilds it."""
    model = load_droid_spec(arm=arm).compile()
    out = []
    for b in range(1, model.nbody):
        name = model.body(b).name
        joints = [{"name": model.joint(j).name, "axis": model.jnt_axis[j].tolist(),
                   "range": model.jnt_range[j].tolist()}
                  for j in range(model.njnt)
                  if model.jnt_bodyid[j] == b and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        sites = [{"name": model.site(s).name, "pos": model.site_pos[s].tolist(), "quat": model.site_quat[s].tolist()}
                 for s in range(model.nsite) if model.site_bodyid[s] == b]
        out.append({"name": name, "parent": model.body(model.body_parentid[b]).name or "world",
                    "pos": model.body_pos[b].tolist(), "quat": model.body_quat[b].tolist(), "joints": joints,
                    "sites": sites})
    return out


def _ours(robot: FrankaDroid, case: dict) -> dict:
    world = mujoco.MjSpec()
    if case["base_size"] is None:
        robot.add_to(world, case["pose"])
    else:
        robot.add_to(world, case["pose"], case["base_size"])
    model = world.compile()
    data = mujoco.MjData(model)
    robot.bind(model).set_qpos(data, "arm", np.array(QPOS))
    mujoco.mj_forward(model, data)
    bodies = {n: np.concatenate([data.xpos[model.body(n).id], data.xquat[model.body(n).id]]) for n in BODIES}
    boxes = [g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body("robot_0/base").id]
    pedestal = {"pos": data.geom_xpos[boxes[0]], "size": model.geom_size[boxes[0]]} if boxes else None
    return {"bodies": bodies, "pedestal": pedestal, "tcp": data.site_xpos[model.site(TCP).id],
            "gravcomp": float(model.body_gravcomp[model.body("robot_0/fr3_link3").id])}


def _same_quat(a, b) -> bool:
    return abs(abs(float(np.dot(a, b))) - 1.0) < 1e-9


@pytest.mark.parametrize("robot_type", ROBOTS, ids=lambda r: r.name)
def test_placement_matches_their_add_robot_to_scene(theirs, robot_type):
    robot = robot_type()
    got = theirs.run("their_placement:placements", {"tree": _tree(robot.arm), "cases": CASES, "bodies": BODIES,
                                                   "tcp": TCP, "qpos": QPOS})["cases"]
    agreed = 0
    for case, their in zip(CASES, got, strict=True):
        ours = _ours(robot, case)
        for name in BODIES:
            assert np.allclose(ours["bodies"][name][:3], their["bodies"][name][:3], atol=1e-9), (case, name)
            assert _same_quat(ours["bodies"][name][3:], their["bodies"][name][3:]), (case, name)
        assert (ours["pedestal"] is None) == (their["pedestal"] is None)
        if ours["pedestal"] is not None:
            assert np.allclose(ours["pedestal"]["pos"], their["pedestal"]["pos"], atol=1e-9)
            assert np.allclose(ours["pedestal"]["size"], their["pedestal"]["size"], atol=1e-12)
        assert np.allclose(ours["tcp"], their["tcp"], atol=1e-9)
        assert ours["gravcomp"] == their["gravcomp"] == 1.0
        agreed += 1
    assert agreed == len(CASES)
