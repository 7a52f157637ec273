"""The libero_rooms scene plugin and pick_v2: deterministic houses, no debug geometry, cost knobs, and a
few steps of one pick_v2 episode end to end (the slow tests regenerate pick_v2 and check it is unchanged)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.libero.rooms import LiberoRooms
from molmo_lerobot.paths import data_path
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Env, Timing
from molmo_lerobot.sim.render_profile import resolve_profile


def pick_v2() -> list[dict]:
    return json.loads((data_path("benchmarks") / "pick_v2" / "benchmark.json").read_text())


def test_houses_are_deterministic_and_every_object_has_its_own_referring_expression():
    scene = LiberoRooms()
    for house in (0, 1, 7, 571):
        meta = scene.metadata(house)
        assert meta == scene.metadata(house)
        expressions = [o["referring_expression"] for o in meta["objects"].values()]
        assert len(set(expressions)) == len(expressions), expressions
        assert any(o["graspable"] for o in meta["objects"].values())


def test_house_build_has_no_debug_geometry_and_honours_the_cost_knobs(monkeypatch, tmp_path):
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path))
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "32")
    monkeypatch.setenv("MOLMO_SCENE_SHADOWS", "0")
    model = LiberoRooms().build(3).compile()
    resolve_profile(None).apply(model)  # the render profile with its MOLMO_SCENE_SHADOWS=0 override
    drawn = Env.camera_view_options().geomgroup
    for g in range(model.ngeom):
        body = model.body(model.geom_bodyid[g]).name
        if body.startswith("libero_") and (model.geom_contype[g] or model.geom_conaffinity[g]):
            assert not drawn[model.geom_group[g]], f"collision geom {model.geom(g).name} is drawn by cameras"
        if model.geom_rgba[g][3] < 1.0 and model.geom_contype[g] == 0:
            assert not drawn[model.geom_group[g]], f"translucent geom {model.geom(g).name} is drawn"
    assert max(model.tex_width.max(), model.tex_height.max()) <= 256  # 32 for ours; MuJoCo's own builtin ones
    assert not model.light_castshadow.any()
    assert model.nlight >= 2


def test_pick_v2_layout(run):
    episodes = pick_v2()
    meta = json.loads((data_path("benchmarks") / "pick_v2" / "benchmark_metadata.json").read_text())
    assert len(episodes) >= 100 and meta["num_houses"] >= 20
    assert meta["camera_system_class"] == "FrankaDroidCameraSystem"
    for ep in episodes:
        spec = parse_episode(ep, run.plugins)
        assert spec.robot.robot_name == "franka_droid" and spec.cameras == [] and spec.task.task_horizon_sec == 20.0
        name = ep["language"]["referral_expressions"]["pickup_obj_name"]
        assert ep["language"]["task_description"] == f"pick up {name}"


def test_a_few_steps_of_one_pick_v2_episode(run, tmp_path, monkeypatch):
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path))
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "64")
    from molmo_lerobot.policies.base import EpisodeContext
    from molmo_lerobot.policies.scripted import ScriptedPick

    spec = parse_episode(pick_v2()[0], run.plugins)
    env = build_env(spec, Timing(), run)
    try:
        env.reset(spec.seed)
        assert env.camera_names == ["wrist_camera", "exo_camera_1"]
        start = env.body_pose(spec.task.pickup_obj_name)
        np.testing.assert_allclose(start, spec.task.pickup_obj_start_pose, atol=1e-4)
        obs = env.observe(images=True)
        for image in obs["images"].values():
            assert image.shape == (224, 224, 3) and image.std() > 10  # a textured room, not a void
        expert = ScriptedPick({})
        expert.reset(EpisodeContext(spec, 0, spec.seed, "", env.move_groups, Timing().policy_dt_s,
                     env=env, catalog=run.catalog))
        for _ in range(3):
            chunk = expert.act(env.observe(images=False))
            for k in range(len(chunk["arm"])):
                env.step({g: v[k] for g, v in chunk.items()})
        assert np.isfinite(env.data.qpos).all()
        assert np.linalg.norm(env.body_pose(spec.task.pickup_obj_name)[:3] - start[:3]) < 0.01  # not yet touched
    finally:
        env.close()


@pytest.mark.slow
def test_pick_v2_regenerates_identically():
    from molmo_lerobot.content.libero.generate import generate_benchmark

    meta = json.loads((data_path("benchmarks") / "pick_v2" / "benchmark_metadata.json").read_text())
    gen = meta["generator"]
    episodes, regenerated = generate_benchmark("pick", gen["n_houses"], gen["episodes_per_house"], gen["seed"],
                                               meta["name"])
    assert json.loads(json.dumps(episodes)) == pick_v2() and json.loads(json.dumps(regenerated)) == meta
