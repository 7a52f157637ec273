"""franka_droid_fr3: franka_droid's FR3 arm built from franky-sim's files, MolmoSpaces' tree kept."""

from __future__ import annotations

from pathlib import Path
from xml.etree import ElementTree

import mujoco
import numpy as np
import pytest

from molmo_lerobot.robots.franka_droid import FrankaDroid, FrankaDroidFR3, fr3_xml

#: MolmoSpaces' FrankaRobotConfig.init_qpos["arm"]
QPOS = [0.0, -0.7853, 0.0, -2.35619, 0.0, 1.57079, 0.0]
POSE = [0.4, -0.2, 0.05, 0.9, 0.0, 0.0, -0.43589]


def _placed(robot):
    world = mujoco.MjSpec()
    robot.add_to(world, POSE, [0.5, 0.5, 0.58])
    model = world.compile()
    data = mujoco.MjData(model)
    robot.bind(model).set_qpos(data, "arm", np.array(QPOS))
    mujoco.mj_forward(model, data)
    return model, data


def test_fr3_arm_is_franky_sims_with_molmospaces_tree_and_tcp():
    source = ElementTree.parse(fr3_xml()).getroot()
    bodies = {b.get("name"): b for b in source.iter("body")}
    joints = {j.get("name"): j for j in source.iter("joint")}
    model, data = _placed(FrankaDroidFR3())
    for k in range(1, 8):  # each link's mass, inertia and joint range are the file's
        body = model.body(f"robot_0/fr3_link{k}")
        inertial = bodies[f"fr3_link{k}"].find("inertial")
        assert body.mass[0] == pytest.approx(float(inertial.get("mass")), rel=1e-12)
        assert sorted(body.inertia) == pytest.approx(sorted(map(float, inertial.get("diaginertia").split())))
        lo, hi = map(float, joints[f"fr3_joint{k}"].get("range").split())
        assert model.joint(f"robot_0/fr3_joint{k}").range.tolist() == [lo, hi]
        assert model.actuator(f"robot_0/fr3_joint{k}").ctrlrange.tolist() == [lo, hi]
        assert model.body_gravcomp[body.id] == 1.0
    # every arm mesh is one of franky-sim's files (none copied here), and the Franka Hand is gone
    arm = {model.body(f"robot_0/fr3_link{k}").id for k in range(8)}
    files = {Path(model.mesh(model.geom_dataid[g]).name).name for g in range(model.ngeom)
             if model.geom_bodyid[g] in arm and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH}
    spec = FrankaDroidFR3().spec()
    mesh_files = {m.name: Path(m.file) for m in spec.meshes}
    arm_files = {mesh_files[name] for name in files}
    assert len(arm_files) >= 30
    assert {p.parent for p in arm_files} == {fr3_xml().parent / "meshes"}
    assert all(p.is_file() for p in arm_files)
    assert not any(name.startswith(("hand", "finger")) for name in mesh_files)
    # the kinematic tree, pedestal, wrist mount and TCP stand where franka_droid's do (MolmoSpaces')
    panda, panda_data = _placed(FrankaDroid())
    for name in ["robot_0/base", *(f"robot_0/fr3_link{k}" for k in range(8)), "robot_0/gripper/base"]:
        assert np.allclose(data.xpos[model.body(name).id], panda_data.xpos[panda.body(name).id], atol=1e-9), name
        assert abs(abs(np.dot(data.xquat[model.body(name).id], panda_data.xquat[panda.body(name).id])) - 1) < 1e-9
    tcp = "robot_0/gripper/grasp_site"
    assert np.allclose(data.site_xpos[model.site(tcp).id], panda_data.site_xpos[panda.site(tcp).id], atol=1e-9)
    assert np.allclose(data.site_xmat[model.site(tcp).id], panda_data.site_xmat[panda.site(tcp).id], atol=1e-9)
    # the masses differ from the Panda's: this is another arm, not a renamed one
    assert model.body("robot_0/fr3_link4").mass[0] != pytest.approx(panda.body("robot_0/fr3_link4").mass[0])


def test_fr3_is_a_robot_of_its_own_with_franka_droids_hand(run):
    robot = run.plugins.robot("franka_droid_fr3")
    assert robot.name == "franka_droid_fr3" and robot.hand == "franka_droid"
    assert run.plugins.robot("franka_droid").arm == "panda"
