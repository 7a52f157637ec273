"""MolmoSpaces' side of tests/parity/test_robot_placement.py: their FrankaRobot.add_robot_to_scene.

Their robot directory is gated, so it is made here in their layout (``model.xml`` + the base
texture their code insists on): ``model.xml`` is our franka_droid arm's kinematic tree (bodies,
hinge joints, TCP site, as our side sends it), loaded by their own ``_load_robot_spec``. Runs in
the parity venv: imports only their package, mujoco and numpy.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import mujoco
import numpy as np


def _write_robot_dir(root: Path, tree: list[dict]) -> None:
    spec = mujoco.MjSpec()
    bodies = {"world": spec.worldbody}
    for b in tree:
        body = bodies[b["parent"]].add_body(name=b["name"], pos=b["pos"], quat=b["quat"])
        body.add_geom(size=[0.01, 0, 0], contype=0, conaffinity=0, mass=0.1)  # mass for the compiler only
        for j in b["joints"]:
            body.add_joint(name=j["name"], type=mujoco.mjtJoint.mjJNT_HINGE, axis=j["axis"], range=j["range"])
        for s in b["sites"]:
            body.add_site(name=s["name"], pos=s["pos"], quat=s["quat"])
        bodies[b["name"]] = body
    (root / "model.xml").write_text(spec.to_xml())
    textures = root / "assets" / "base_textures"
    textures.mkdir(parents=True)
    from PIL import Image

    Image.new("RGB", (8, 8), (84, 61, 43)).save(textures / "DarkWood2.png")


def placements(inputs: dict) -> dict:
    """For each case (pose, base_size): their scene assembly at the origin, then the base moved to the
    pose as their eval does (``set_world_pose`` through the mocap base); poses of the named bodies,
    the pedestal geom (centre, half sizes) and the TCP site at ``qpos``."""
    from molmo_spaces.configs.robot_configs import FrankaRobotConfig
    from molmo_spaces.robots.franka import FrankaRobot
    from molmo_spaces.robots.robot_views.franka_fr3_view import FrankaFR3BaseGroup
    from scipy.spatial.transform import Rotation as R

    out = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        _write_robot_dir(root, inputs["tree"])
        for case in inputs["cases"]:
            config = FrankaRobotConfig(robot_dir=root, base_size=case["base_size"])
            spec = mujoco.MjSpec()
            FrankaRobot.add_robot_to_scene(config, spec, prefix=config.robot_namespace, pos=[0.0, 0.0],
                                           quat=[1.0, 0.0, 0.0, 0.0])
            FrankaRobot.apply_control_overrides(spec, config)
            model = spec.compile()
            data = mujoco.MjData(model)
            pose = np.eye(4)
            pose[:3, 3] = case["pose"][:3]
            pose[:3, :3] = R.from_quat(case["pose"][3:], scalar_first=True).as_matrix()
            FrankaFR3BaseGroup(data, config.robot_namespace).pose = pose
            for k, q in enumerate(inputs["qpos"], start=1):
                data.qpos[model.jnt_qposadr[model.joint(f"robot_0/fr3_joint{k}").id]] = q
            mujoco.mj_forward(model, data)
            bodies = {n: np.concatenate([data.xpos[model.body(n).id], data.xquat[model.body(n).id]]).tolist()
                      for n in inputs["bodies"]}
            boxes = [g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body("robot_0/base").id]
            pedestal = ({"pos": data.geom_xpos[boxes[0]].tolist(), "size": model.geom_size[boxes[0]].tolist()}
                        if boxes else None)
            site = model.site(inputs["tcp"]).id
            out.append({"bodies": bodies, "pedestal": pedestal, "tcp": data.site_xpos[site].tolist(),
                        "gravcomp": float(model.body_gravcomp[model.body("robot_0/fr3_link3").id])})
    return {"cases": out}
