"""franka_droid: Franka + Robotiq 2F-85 with MolmoSpaces' names, init_qpos, TCP and grasp conventions."""

from __future__ import annotations

import copy
import json
import os
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.assets.catalog import default_catalog  # noqa: E402
from molmo_lerobot.benchmark.schema import EpisodeSpec  # noqa: E402
from molmo_lerobot.config import compose  # noqa: E402
from molmo_lerobot.paths import data_path  # noqa: E402
from molmo_lerobot.plugins import get_plugins  # noqa: E402
from molmo_lerobot.robots import franka_droid  # noqa: E402
from molmo_lerobot.runner.episode_env import build_env  # noqa: E402
from molmo_lerobot.runner.evaluate import run_evaluation  # noqa: E402
from molmo_lerobot.sim.env import Timing  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tasks"))
from droid_variants import OPEN_DRIVERS, droid_episode  # noqa: E402

#: MolmoSpaces' FrankaRobotConfig.init_qpos and a wrist camera as their benchmark files write it
MS_INIT_QPOS = {"base": [], "arm": [0, -0.7853, 0, -2.35619, 0, 1.57079, 0.0], "gripper": [0.00296, 0.00296]}
MS_WRIST = {"name": "wrist_camera", "type": "robot_mounted", "reference_body_names": ["robot_0/gripper/base"],
            "camera_offset": [0.0341, 0.0780, 0.0231], "lookat_offset": [0.0, 0.0, 0.08],
            "camera_quaternion": [0.00737, -0.00590, 0.98836, 0.15186], "fov": 48.16, "record_depth": False}


def pick_episode(k: int = 0) -> dict:
    return json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[k]


def ms_pick_episode(k: int = 0) -> dict:
    """A pick_v1 episode rewritten as MolmoSpaces writes franka_droid episodes (their init_qpos and wrist camera)."""
    raw = copy.deepcopy(pick_episode(k))
    raw["robot"] = {"robot_name": "franka_droid", "init_qpos": copy.deepcopy(MS_INIT_QPOS)}
    exo = next(c for c in raw["cameras"] if c["type"] == "exocentric")
    raw["cameras"] = [MS_WRIST, {**exo, "name": "exo_camera_1"}]
    raw["source"] = {"h5_file": "none.h5", "traj_key": "traj_0", "camera_system_class": "FrankaRandomizedDroidCameraSystem"}
    return raw


def _env(raw: dict, camera_system: str | None = None):
    spec = EpisodeSpec.model_validate(raw)
    env = build_env(spec, Timing(), get_plugins(), camera_system)
    env.reset(0)
    return env


def _pad_gap(env) -> float:
    m, d = env.model, env.data
    l, r = (m.geom(f"robot_0/gripper/{s}_fingerpad_collision").id for s in ("left", "right"))
    return float(np.linalg.norm(d.geom_xpos[l] - d.geom_xpos[r]))


def test_molmospaces_names_resolve():
    env = _env(ms_pick_episode())
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


def test_molmospaces_init_qpos_starts_open():
    env = _env(ms_pick_episode())
    try:
        assert env.observe(images=False)["qpos"]["gripper"][0] < 0.01
        assert _pad_gap(env) > 0.08  # a 2F-85 opens to 85 mm
        assert env.robot.driver_angles(env.data) == pytest.approx(OPEN_DRIVERS, abs=1e-6)
    finally:
        env.close()


def test_gripper_command_spans_the_full_robotiq_travel():
    env = _env(ms_pick_episode())
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


def test_tcp_follows_the_unified_convention():
    """On the axis between the fingers, +z towards the fingertips, fingers opening along ±y, fingertips
    3.5 cm beyond it (like the Panda's tcp)."""
    env = _env(ms_pick_episode())
    m, d = env.model, env.data
    try:
        env.robot.set_qpos(d, "gripper", [0.5])
        mujoco.mj_forward(m, d)
        site = env.robot.tcp_site
        R, p = d.site_xmat[site].reshape(3, 3), d.site_xpos[site]
        l, r = (m.geom(f"robot_0/gripper/{s}_fingerpad_collision").id for s in ("left", "right"))
        mid = R.T @ ((d.geom_xpos[l] + d.geom_xpos[r]) / 2 - p)
        across = R.T @ (d.geom_xpos[l] - d.geom_xpos[r])
        assert np.abs(mid[:2]).max() < 1e-3 and 0.0 < mid[2] < 0.02  # pads just beyond it, centred
        from molmo_lerobot.assets.builtin import TCP_TO_FINGERTIP
        tip = m.geom("robot_0/gripper/left_fingertip_collision").id
        depth = (R.T @ (d.geom_xpos[tip] - p))[2] + m.geom_size[tip][2]
        assert depth == pytest.approx(TCP_TO_FINGERTIP, abs=0.004)
        assert abs(across[1]) == pytest.approx(np.linalg.norm(across), rel=1e-3)
        base = d.xpos[m.body("robot_0/gripper/base").id]
        assert (R.T @ (p - base))[2] > 0.1  # +z points from the wrist to the fingertips
    finally:
        env.close()


def test_franka_keeps_its_panda_hand():
    plugins = get_plugins()
    assert plugins.robot("franka").name == "franka" and plugins.robot("franka_droid").name == "franka_droid"
    assert "franka_droid" not in plugins.robot("franka").aliases


def test_molmospaces_grasp_file_transfers(tmp_path):
    """A grasp written in MolmoSpaces' convention (``transforms``: the TCP pose in the object's frame,
    +z approach, fingers along ±y) for franka_droid is what the expert uses, and it picks the object
    up with it. (The file sits in our grasp-library layout, ``<robot>/<uid>.npz``.)"""
    raw = droid_episode(pick_episode(0))
    uid = raw["task"]["pickup_obj_name"]
    # one top-down grasp: TCP 1 cm above the object's origin, approach -z (world down), fingers along x
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    T[2, 3] = 0.01
    (tmp_path / "franka_droid").mkdir(parents=True)
    np.savez(tmp_path / "franka_droid" / f"{uid}.npz", transforms=T[None])
    catalog = default_catalog()
    saved = list(catalog.grasp_libraries)
    catalog.register_grasp_library(tmp_path)
    from molmo_lerobot.policies.scripted import ScriptedPick, object_grasps
    from molmo_lerobot.policies.base import EpisodeContext
    from molmo_lerobot.runner.rollout import rollout
    env = _env(raw)
    try:
        assert object_grasps(env, uid) == pytest.approx(T[None])
        spec = env.spec
        task = get_plugins().task_type(spec.task_name).create(spec, env)
        ctx = EpisodeContext(spec=spec, episode_index=0, seed=0, prompt="", move_groups=dict(env.move_groups),
                             policy_dt_s=0.066, env=env)
        out = rollout(env, task, ScriptedPick({}), ctx, 120, [], None, "scripted")
        assert out.success
    finally:
        env.close()
        catalog.grasp_libraries[:] = saved


def test_their_model_is_loaded_when_installed(tmp_path, monkeypatch):
    """With MolmoSpaces' assets dir holding robots/franka_droid/model.xml, that file is the robot."""
    robot_dir = tmp_path / "robots" / "franka_droid"
    robot_dir.mkdir(parents=True)
    world = mujoco.MjSpec()
    base = world.worldbody.add_body(name="base")
    base.add_geom(name="their_marker", size=[0.01, 0.01, 0.01], type=mujoco.mjtGeom.mjGEOM_BOX)
    base.add_frame().attach_body(mujoco.MjSpec.from_string(franka_droid._registry_xml()).body("fr3_link0"), "", "")
    (robot_dir / "model.xml").write_text(world.to_xml())
    monkeypatch.setenv("MLSPACES_ASSETS_DIR", str(tmp_path))
    assert franka_droid.molmospaces_model() == robot_dir / "model.xml"
    w = mujoco.MjSpec()
    franka_droid.FrankaDroid().add_to(w, [0, 0, 0, 1, 0, 0, 0])
    m = w.compile()
    assert m.geom("robot_0/their_marker").id >= 0
    franka_droid.FrankaDroid().bind(m)


def test_molmospaces_pick_episode_runs_and_records_an_open_gripper(tmp_path):
    """Must-show: their wrist camera spec and init_qpos on franka_droid through molmo-eval; the first
    recorded frame has the gripper open; the scripted expert picks."""
    bench = tmp_path / "ms_pick"
    bench.mkdir()
    (bench / "benchmark.json").write_text(json.dumps([ms_pick_episode(0)]))
    cfg = compose(["policy=scripted", f"benchmark.path={bench}", "workers=1", "record=true",
                   f"output_dir={tmp_path / 'run'}", "progress=false"])
    res = run_evaluation(cfg)
    assert res.summary["n_errors"] == 0 and res.summary["n_success"] == 1
    import pandas as pd
    frames = pd.concat(pd.read_parquet(p) for p in sorted((tmp_path / "run" / "dataset" / "data").rglob("*.parquet")))
    first = np.asarray(frames.sort_values("frame_index").iloc[0]["observation.state"])
    assert first[-1] < 0.01  # gripper entry: 0 = open


def test_pi0_against_a_droid_server_on_franka_droid(tmp_path):
    """Must-show: policy=pi0 over openpi's protocol on franka_droid with the DROID cameras (cameras: []),
    0 errors; the server's gripper commands 0 … 1 drive the Robotiq over its full travel."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "protocol"))
    from droid_server import FakeDroidServer

    bench = tmp_path / "droid_pick"
    bench.mkdir()
    (bench / "benchmark.json").write_text(json.dumps([droid_episode(pick_episode(k)) for k in (0, 1)]))
    with FakeDroidServer(horizon=15, velocity=0.0).running() as srv:
        cfg = compose(["policy=pi0", f"policy.port={srv.port}", "workers=1", f"benchmark.path={bench}",
                       "horizon=30", "record=true", f"output_dir={tmp_path / 'run'}", "progress=false"])
        res = run_evaluation(cfg)
    assert srv.errors == [] and res.summary["n_errors"] == 0 and res.summary["n_episodes"] == 2
    assert all(e.extra["camera_system"] == "FrankaDroidCameraSystem" for e in res.episodes)
    import pandas as pd
    frames = pd.concat(pd.read_parquet(p) for p in sorted((tmp_path / "run" / "dataset" / "data").rglob("*.parquet")))
    commanded = np.stack(frames["action"].to_numpy())[:, -1]
    observed = np.stack(frames["observation.state"].to_numpy())[:, -1]
    assert commanded.min() == pytest.approx(0.0, abs=1e-6) and commanded.max() == pytest.approx(1.0, abs=1e-6)
    assert observed.min() < 0.02 and observed.max() > 0.9  # open … closed: the whole 2F-85 travel
