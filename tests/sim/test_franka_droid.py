"""franka_droid: Franka + Robotiq 2F-85 with MolmoSpaces' names, init_qpos, TCP and grasp conventions."""

from __future__ import annotations

import copy
import json
import os
from xml.etree import ElementTree

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from droid_variants import OPEN_DRIVERS, droid_episode, on_pedestal

from molmo_lerobot.config import compose
from molmo_lerobot.context import RunContext
from molmo_lerobot.molmospaces.user import register_user_grasp_library
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.robots import franka_droid
from molmo_lerobot.runner.evaluate import run_evaluation

#: MolmoSpaces' FrankaRobotConfig.init_qpos and a wrist camera as their benchmark files write it
MS_INIT_QPOS = {"base": [], "arm": [0, -0.7853, 0, -2.35619, 0, 1.57079, 0.0], "gripper": [0.00296, 0.00296]}
MS_WRIST = {"name": "wrist_camera", "type": "robot_mounted", "reference_body_names": ["robot_0/gripper/base"],
            "camera_offset": [0.0341, 0.0780, 0.0231], "lookat_offset": [0.0, 0.0, 0.08],
            "camera_quaternion": [0.00737, -0.00590, 0.98836, 0.15186], "fov": 48.16, "record_depth": False}


def pick_episode(k: int = 0) -> dict:
    return json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[k]


def ms_pick_episode(k: int = 0) -> dict:
    """A pick_v1 episode rewritten as MolmoSpaces writes franka_droid episodes (their init_qpos and wrist camera)."""
    raw = on_pedestal(pick_episode(k))
    raw["robot"] = {"robot_name": "franka_droid", "init_qpos": copy.deepcopy(MS_INIT_QPOS)}
    exo = next(c for c in raw["cameras"] if c["type"] == "exocentric")
    raw["cameras"] = [MS_WRIST, {**exo, "name": "exo_camera_1"}]
    raw["source"] = {"h5_file": "none.h5", "traj_key": "traj_0",
                     "camera_system_class": "FrankaRandomizedDroidCameraSystem"}
    return raw


def _pad_gap(env) -> float:
    m, d = env.model, env.data
    left, right = (m.geom(f"robot_0/gripper/{s}_fingerpad_collision").id for s in ("left", "right"))
    return float(np.linalg.norm(d.geom_xpos[left] - d.geom_xpos[right]))


def test_molmospaces_names_resolve(episode_env):
    env = episode_env(ms_pick_episode())
    m = env.model
    try:
        for body in ("robot_0/base", "robot_0/fr3_link0", "robot_0/gripper/base"):
            assert m.body(body).id > 0
        for k in range(1, 8):
            assert m.joint(f"robot_0/fr3_joint{k}").id >= 0 and m.actuator(f"robot_0/fr3_joint{k}").id >= 0
        assert m.joint("robot_0/gripper/left_driver_joint").id >= 0
        assert m.actuator("robot_0/gripper/fingers_actuator").id >= 0
        assert tuple(m.actuator_ctrlrange[m.actuator("robot_0/gripper/fingers_actuator").id]) == (0.0, 255.0)
        assert m.site("robot_0/gripper/grasp_site").id == env.robot.tcp_site
        assert m.camera("robot_0/gripper/wrist_camera").id >= 0
        assert env.camera_names == ["wrist_camera", "exo_camera_1"]  # their wrist spec mounts on gripper/base
        assert m.cam_bodyid[m.camera("wrist_camera").id] == m.body("robot_0/gripper/base").id
        assert env.camera_system == "standard"  # the episode's own cameras win
    finally:
        env.close()


def test_molmospaces_init_qpos_starts_open(episode_env):
    env = episode_env(ms_pick_episode())
    try:
        assert env.observe(images=False)["qpos"]["gripper"][0] < 0.01
        assert _pad_gap(env) > 0.08  # a 2F-85 opens to 85 mm
        assert env.robot.joint_qpos(env.data, "gripper") == pytest.approx(OPEN_DRIVERS, abs=1e-6)
    finally:
        env.close()


def test_their_driver_angles_start_the_driver_joints_alone(episode_env):
    """MolmoSpaces' gripper group writes its two driver joints only: the finger linkage starts where the
    reset leaves it (0) and the joint equalities pull it along; one normalized value starts all of it."""
    linkage = [f"robot_0/gripper/{name}" for name in franka_droid._FOLLOWERS]
    for gripper, drivers, links in (([0.4, 0.3], [0.4, 0.3], [0.0] * 4), ([0.5], [0.4, 0.4], [0.4, -0.4, 0.4, -0.4])):
        raw = ms_pick_episode()
        raw["robot"]["init_qpos"]["gripper"] = gripper
        env = episode_env(raw)
        try:
            m, d = env.model, env.data
            assert env.robot.joint_qpos(d, "gripper").tolist() == drivers
            assert [float(d.qpos[m.jnt_qposadr[m.joint(j).id]]) for j in linkage] == pytest.approx(links, abs=1e-15)
            assert env.robot.targets(d, "gripper") == pytest.approx([float(np.mean(drivers)) / 0.8])
        finally:
            env.close()


def test_gripper_command_spans_the_full_robotiq_travel(episode_env):
    env = episode_env(ms_pick_episode())
    u = env.model.actuator("robot_0/gripper/fingers_actuator").id
    try:
        arm = env.robot.targets(env.data, "arm")
        gaps = {}
        for g in (0.0, 1.0):
            for _ in range(10):
                env.step({"arm": arm, "gripper": np.array([g])})
            assert env.data.ctrl[u] == pytest.approx(255.0 * g)
            assert env.observe(images=False)["qpos"]["gripper"][0] == pytest.approx(g, abs=0.03)
            gaps[g] = _pad_gap(env)
        assert gaps[0.0] > 0.08 and gaps[1.0] < 0.01
    finally:
        env.close()


def _in_tcp(d, site, points):
    R, p = d.site_xmat[site].reshape(3, 3), d.site_xpos[site]
    return (np.atleast_2d(points) - p) @ R


def _geom_points(m, d, g):
    """The geom's mesh vertices or bounding-box corners (box, capsule), in world coordinates."""
    corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
    if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
        mid = m.geom_dataid[g]
        local = m.mesh_vert[m.mesh_vertadr[mid]:m.mesh_vertadr[mid] + m.mesh_vertnum[mid]]
    elif m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
        r, half = m.geom_size[g][:2]
        local = corners * [r, r, half + r]
    else:
        local = corners * m.geom_size[g]
    return local @ d.geom_xmat[g].reshape(3, 3).T + d.geom_xpos[g]


def test_tcp_is_the_pinch_point_in_the_unified_convention(episode_env):
    """The TCP is where the pad centres meet when the fingers close (MolmoSpaces' gripping centre):
    +z towards the fingertips, fingers along ±y; ROBOTIQ_2F85 (the hand the built-in grasps and the
    expert assume) matches the model: fingertip reach, palm distance, open span."""
    from molmo_lerobot.assets.builtin import ROBOTIQ_2F85

    env = episode_env(ms_pick_episode())
    m, d = env.model, env.data
    site = env.robot.tcp_site
    pads = [m.geom(f"robot_0/gripper/{s}_fingerpad_collision").id for s in ("left", "right")]
    tips = [m.geom(f"robot_0/gripper/{s}_fingertip_collision").id for s in ("left", "right")]
    try:
        env.robot.set_qpos(d, "gripper", [1.0])
        mujoco.mj_forward(m, d)
        mid = _in_tcp(d, site, (d.geom_xpos[pads[0]] + d.geom_xpos[pads[1]]) / 2)[0]
        assert np.abs(mid).max() < 2e-3  # closed: the pads' centre is the TCP
        reach = max(_in_tcp(d, site, _geom_points(m, d, g))[:, 2].max() for g in tips)
        assert reach == pytest.approx(ROBOTIQ_2F85.tcp_to_fingertip, abs=2e-3)
        env.robot.set_qpos(d, "gripper", [0.0])
        mujoco.mj_forward(m, d)
        across = _in_tcp(d, site, d.geom_xpos[pads[0]])[0] - _in_tcp(d, site, d.geom_xpos[pads[1]])[0]
        assert abs(across[1]) == pytest.approx(np.linalg.norm(across), rel=1e-3)  # fingers open along ±y
        widest = max(np.abs(_in_tcp(d, site, _geom_points(m, d, g))[:, 1]).max() for g in tips)
        assert widest <= ROBOTIQ_2F85.open_half_span
        palm = _in_tcp(d, site, _geom_points(m, d, m.geom("robot_0/gripper/hand_collision").id))[:, 2].max()
        assert -palm == pytest.approx(ROBOTIQ_2F85.palm_to_tcp, abs=2e-3)
        base = d.xpos[m.body("robot_0/gripper/base").id]
        assert -_in_tcp(d, site, base)[0, 2] > 0.1  # +z points from the wrist to the fingertips
    finally:
        env.close()


def test_panda_hand_geometry_matches_the_model(episode_env):
    """PANDA_HAND (franka's analytic grasps and expert): the tcp site sits mid-way along the
    fingers' contact capsules, with the fingertips tcp_to_fingertip beyond it."""
    from molmo_lerobot.assets.builtin import PANDA_HAND

    raw = pick_episode(0)
    env = episode_env(raw)
    m, d = env.model, env.data
    try:
        mujoco.mj_forward(m, d)
        fingers = [g for g in range(m.ngeom) if "finger" in m.body(m.geom_bodyid[g]).name
                   and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE and m.geom_contype[g]]
        assert len(fingers) >= 2
        z = np.concatenate([_in_tcp(d, env.robot.tcp_site, _geom_points(m, d, g))[:, 2] for g in fingers])
        assert z.max() == pytest.approx(PANDA_HAND.tcp_to_fingertip, abs=2e-3)
        assert abs((z.max() + z.min()) / 2) < 2e-3
    finally:
        env.close()


def test_franka_keeps_its_panda_hand():
    plugins = Plugins()
    assert plugins.robot("franka").name == "franka" and plugins.robot("franka_droid").name == "franka_droid"
    assert "franka_droid" not in plugins.robot("franka").aliases


@pytest.mark.parametrize("robot", ["franka", "franka_droid"])
def test_a_base_pose_without_7_values_is_one_clear_error(robot):
    with pytest.raises(ValueError, match=r"robot_base_pose needs 7 values .* got 3"):
        Plugins().robot(robot).add_to(mujoco.MjSpec(), [0.0, 0.0, 0.0])


def test_molmospaces_grasp_file_transfers(tmp_path, episode_env):
    """A user grasp library exactly as MolmoSpaces' custom-assets tutorial writes one
    (``<uid>/droid/grasps.npz`` + ``grasps_index.json``, ``transforms`` float16 as their pipeline
    saves them): one top-down grasp with the TCP at the block's origin, +y fingers along the
    object's -y (turned 0.5 rad about z), +z approach pointing down. The expert uses it on
    franka_droid and picks the block without the fingers touching the table: the pinch point at
    the block's centre keeps the fingertips off it (the old, shallower TCP pressed them into it)."""
    raw = droid_episode(next(e for e in map(pick_episode, range(60))
                             if e["task"]["pickup_obj_name"].startswith("builtin_red_block")))
    uid = raw["task"]["pickup_obj_name"]
    T = np.eye(4)
    T[:3, 1] = [0, -1, 0]
    T[:3, 2] = [0, 0, -1]
    yaw = 0.5  # turned about the block's z, so float16 rounds the rotation as in their files
    T[:3, :3] = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]) @ T[:3, :3]
    T = T.astype(np.float16).astype(np.float64)
    assert not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6)  # not quite a rotation
    lib = tmp_path / "grasp_library"
    (lib / uid / "droid").mkdir(parents=True)
    np.savez_compressed(lib / uid / "droid" / "grasps.npz", transforms=T.reshape(1, 4, 4).astype(np.float16))
    (lib / "grasps_index.json").write_text(json.dumps(
        {"grasp_paths": {"droid": {uid: f"{uid}/droid/grasps.npz"}}, "articulated_grasp_paths": {}}))
    run = RunContext.build()
    register_user_grasp_library(run.catalog, "tutorial", lib, "builtin")
    from molmo_lerobot.policies.expert_motion import object_grasps
    from molmo_lerobot.policies.scripted_pick import ScriptedPick
    from molmo_lerobot.runner.episode import EpisodeSession
    from molmo_lerobot.runner.plan import plan_spec
    from molmo_lerobot.runner.rollout import rollout
    env = episode_env(raw, run=run)
    try:
        assert object_grasps(env, uid, run.catalog) == pytest.approx(T[None])
        spec = env.spec
        task = run.plugins.task_type(spec.task_name).create(spec, env)
        env.step({g: env.robot.targets(env.data, g) for g in env.move_groups})  # the block settles
        support = env.contact_bodies(env.subtree_bodies(uid)) - env.robot.body_ids  # what it rests on
        assert support
        touched, step = [], env.step

        def step_and_check(action):
            step(action)
            touched.append(bool(env.contact_bodies(env.robot.body_ids) & support))

        env.step = step_and_check
        expert = ScriptedPick({})
        plan = plan_spec(spec, run.plugins, seed=0, horizon=120)
        out = rollout(EpisodeSession.start(plan, spec, env, task, run, policy=expert), expert, [], "scripted")
        assert expert.grasp_local == pytest.approx(T)
        assert out.success
        assert not any(touched)  # the fingers never reach the table: the pads centre on the block
    finally:
        env.close()


def test_their_model_is_loaded_when_installed(tmp_path, monkeypatch):
    """With MolmoSpaces' assets dir holding robots/franka_droid/model.xml, that file is the robot, used
    as their add_robot_to_scene uses it: its fr3_link0 subtree on our mount and pedestal, every body
    gravity-compensated (their FrankaRobotConfig.gravcomp); the file's own top body is not carried."""
    robot_dir = tmp_path / "robots" / "franka_droid"
    robot_dir.mkdir(parents=True)
    arm = mujoco.MjSpec.from_string(franka_droid._registry_xml())
    for body in arm.bodies:
        body.gravcomp = 0.0
    arm.body("fr3_link0").add_geom(name="their_marker", size=[0.01, 0.01, 0.01], type=mujoco.mjtGeom.mjGEOM_BOX)
    root = ElementTree.fromstring(arm.to_xml())  # their file: a top body "base" holding fr3_link0
    worldbody = root.find("worldbody")
    base = ElementTree.SubElement(worldbody, "body", name="base")
    ElementTree.SubElement(base, "geom", name="their_base_marker", type="box", size="0.01 0.01 0.01")
    link0 = worldbody.find("body[@name='fr3_link0']")
    worldbody.remove(link0)
    base.append(link0)
    (robot_dir / "model.xml").write_text(ElementTree.tostring(root, encoding="unicode"))
    monkeypatch.setenv("MLSPACES_ASSETS_DIR", str(tmp_path))
    assert franka_droid.molmospaces_model() == robot_dir / "model.xml"
    w = mujoco.MjSpec()
    franka_droid.FrankaDroid().add_to(w, [0, 0, 0, 1, 0, 0, 0], franka_droid.BASE_SIZE)
    m = w.compile()
    assert m.geom_bodyid[m.geom("robot_0/their_marker").id] == m.body("robot_0/fr3_link0").id
    assert "robot_0/their_base_marker" not in {m.geom(i).name for i in range(m.ngeom)}
    assert m.body_gravcomp[m.body("robot_0/fr3_link4").id] == 1.0
    assert m.body("robot_0/fr3_link0").pos[2] == pytest.approx(0.58)
    franka_droid.FrankaDroid().bind(m)


@pytest.mark.slow  # the default run keeps it under 10 minutes; make test-all runs it
def test_molmospaces_pick_episode_runs_and_records_an_open_gripper(tmp_path, fork_servers):
    """Must-show: their wrist camera spec and init_qpos on franka_droid through molmo-eval; the first
    recorded frame has the gripper open; the scripted expert picks."""
    bench = tmp_path / "ms_pick"
    bench.mkdir()
    (bench / "benchmark.json").write_text(json.dumps([ms_pick_episode(0)]))
    cfg = compose(["policy=scripted", f"benchmark.path={bench}", "workers=1", "record=true", "end_on_success=true",
                   f"output_dir={tmp_path / 'run'}", "progress=false"])
    res = run_evaluation(cfg, fork_servers)
    assert res.summary["n_errors"] == 0 and res.summary["n_success"] == 1
    import pandas as pd
    frames = pd.concat(pd.read_parquet(p) for p in sorted((tmp_path / "run" / "dataset" / "data").rglob("*.parquet")))
    first = np.asarray(frames.sort_values("frame_index").iloc[0]["observation.state"])
    assert first[-1] < 0.01  # gripper entry: 0 = open


def test_pi0_against_a_droid_server_on_franka_droid(droid_recording):
    """Must-show: policy=pi0 over openpi's protocol on franka_droid with the DROID cameras (cameras: []),
    0 errors; the server's gripper commands 0 … 1 drive the Robotiq over its full travel."""
    _, out, res, srv = droid_recording
    assert srv.errors == [] and res.summary["n_errors"] == 0 and res.summary["n_episodes"] == 2
    assert all(e.extra["camera_system"] == "FrankaDroidCameraSystem" for e in res.episodes)
    import pandas as pd
    frames = pd.concat(pd.read_parquet(p) for p in sorted((out / "dataset" / "data").rglob("*.parquet")))
    commanded = np.stack(frames["action"].to_numpy())[:, -1]
    observed = np.stack(frames["observation.state"].to_numpy())[:, -1]
    assert commanded.min() == pytest.approx(0.0, abs=1e-6) and commanded.max() == pytest.approx(1.0, abs=1e-6)
    assert observed.min() < 0.02 and observed.max() > 0.9  # open … closed: the whole 2F-85 travel
