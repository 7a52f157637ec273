"""pick_and_place_v2, next_to_v2 and color_v2 (``libero.generate --task pick_and_place|next_to|color``):
deterministic generation, the published files validate and say what their episodes hold, ``--task pick``
still writes pick_v2's episodes, and the first steps of one episode. The slow tests regenerate each
published benchmark and play one episode of each with the scripted expert to success."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.benchmark.validate import validate_benchmark
from molmo_lerobot.content.libero.generate import TASKS, generate_benchmark
from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS
from molmo_lerobot.content.libero.rooms import LiberoRooms, resting_radius
from molmo_lerobot.paths import data_path
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing

#: benchmark -> its ``--task``
BENCHMARKS = {"pick_and_place_v2": "pick_and_place", "next_to_v2": "next_to", "color_v2": "color"}


def _files(name: str) -> tuple[list[dict], dict]:
    root = data_path("benchmarks") / name
    return (json.loads((root / "benchmark.json").read_text()),
            json.loads((root / "benchmark_metadata.json").read_text()))


def test_receptacle_openings_come_from_the_geometry():
    """Inside every receptacle's rim, narrower than its outside, wider for the bigger one of a kind."""
    openings = {u: o.opening_radius for u, o in LIBERO_OBJECTS.items() if o.receptacle}
    for uid, r in openings.items():
        assert 0.02 < r < min(LIBERO_OBJECTS[uid].half_extents[:2]), (uid, r)
        assert LIBERO_OBJECTS[uid].metadata()["opening_radius"] == round(r, 3)
    assert openings["libero_white_bowl"] < openings["libero_black_bowl"] < openings["libero_basket"]
    assert openings["libero_plate"] == openings["libero_yellow_plate"]


@pytest.mark.parametrize("task", ["pick_and_place", "next_to", "color"])
def test_generation_is_deterministic(task):
    scene = LiberoRooms()
    first = [TASKS[task].episode(scene, 571, i, 3, task) for i in range(2)]
    again = [TASKS[task].episode(scene, 571, i, 3, task) for i in range(2)]
    assert json.dumps(first) == json.dumps(again)
    assert first[0] != first[1]


def test_pick_still_generates_pick_v2():
    """``--task pick`` is unchanged: its episode function writes pick_v2's episodes (the slow test in
    test_libero_rooms.py regenerates the whole file)."""
    episodes, meta = _files("pick_v2")
    scene = LiberoRooms()
    seed, per_house = meta["generator"]["seed"], meta["generator"]["episodes_per_house"]
    for k in (0, 7):
        house, index = episodes[k]["house_index"], k % per_house
        assert TASKS["pick"].episode(scene, house, index, seed, "pick") == episodes[k]


@pytest.mark.parametrize("name", sorted(BENCHMARKS))
def test_published_benchmark_validates_and_holds_its_task(name, run):
    episodes, meta = _files(name)
    task = BENCHMARKS[name]
    assert len(episodes) >= 100 and meta["num_houses"] >= 20 and meta["generator"]["task"] == task
    assert meta["camera_system_class"] == "FrankaDroidCameraSystem"
    assert validate_benchmark(load_benchmark(data_path("benchmarks") / name, run.plugins), run.plugins, run) == []
    scene = LiberoRooms()
    for ep in episodes:
        spec = parse_episode(ep, run.plugins)
        assert run.plugins.task_type(spec.task_name).name == TASKS[task].task_type
        assert spec.task.task_horizon_sec == TASKS[task].horizon_sec
        assert spec.robot.robot_name == "franka_droid" and spec.cameras == []
        house = scene.metadata(ep["house_index"])["objects"]
        pick, target = ep["task"]["pickup_obj_name"], ep["task"]["place_receptacle_name"]
        assert house[pick]["graspable"] and house[target]["receptacle"]
        said = ep["language"]["referral_expressions"]
        what, where = said["pickup_obj_name"], said["place_receptacle_name"]
        assert said == {"pickup_obj_name": house[pick]["referring_expression"],
                        "place_receptacle_name": house[target]["referring_expression"]}
        poses = ep["scene_modifications"]["object_poses"]
        assert poses[pick] == ep["task"]["pickup_obj_start_pose"] and poses[target] == ep["task"][
            "place_receptacle_start_pose"]
        if task == "next_to":
            assert ep["language"]["task_description"] == f"put {what} next to {where}"
            continue
        assert resting_radius(LIBERO_OBJECTS[pick]) <= LIBERO_OBJECTS[target].opening_radius
        word = "on" if house[target]["category"] in ("plate", "tray") else "in"
        assert ep["language"]["task_description"] == f"put {what} {word} {where}"
        if task == "color":  # the other receptacle differs from the target only in colour, and the words say which
            (other,) = ep["task"]["other_receptacle_names"]
            assert house[other]["category"] == house[target]["category"]
            assert house[other]["color"] != house[target]["color"] and house[target]["color"] in where
            assert ep["task"]["other_receptacle_start_poses"] == {other: poses[other]}


def test_first_steps_of_one_color_v2_episode(run, tmp_path, monkeypatch):
    """The scene builds with DROID cameras, nothing is solved at the start, the expert plans its grasp and
    approaches without disturbing the scene."""
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path))
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "64")
    from molmo_lerobot.policies.base import EpisodeContext
    from molmo_lerobot.policies.scripted_place import ScriptedPlace

    spec = parse_episode(_files("color_v2")[0][0], run.plugins)
    env = build_env(spec, Timing(), run)
    try:
        env.reset(spec.seed)
        task = run.plugins.task_type(spec.task_name).create(spec, env)
        task.setup()
        assert env.camera_names == ["wrist_camera", "exo_camera_1"] and not task.success()
        names = [spec.task.pickup_obj_name, spec.task.place_receptacle_name, *spec.task.other_receptacle_names]
        start = {n: env.body_pose(n) for n in names}
        for n in names:
            np.testing.assert_allclose(start[n], spec.scene_modifications.object_poses[n], atol=2e-3)
        expert = ScriptedPlace({})
        expert.reset(EpisodeContext(spec, 0, spec.seed, "", env.move_groups, Timing().policy_dt_s,
                     env=env, catalog=run.catalog))
        for _ in range(3):
            chunk = expert.act(env.observe(images=False))
            for k in range(len(chunk["arm"])):
                env.step({g: v[k] for g, v in chunk.items()})
        assert np.isfinite(env.data.qpos).all() and not task.success()
        for n in names:
            assert np.linalg.norm(env.body_pose(n)[:3] - start[n][:3]) < 0.01, f"{n} moved before the grasp"
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(BENCHMARKS))
def test_published_benchmark_regenerates_identically(name):
    episodes, meta = _files(name)
    gen = meta["generator"]
    again, again_meta = generate_benchmark(gen["task"], gen["n_houses"], gen["episodes_per_house"], gen["seed"],
                                           meta["name"])
    assert json.loads(json.dumps(again)) == episodes and json.loads(json.dumps(again_meta)) == meta


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(BENCHMARKS))
def test_scripted_expert_solves_the_first_episode(name, tmp_path):
    from molmo_lerobot.config import compose
    from molmo_lerobot.runner.evaluate import run_evaluation

    results = run_evaluation(compose(["policy=scripted", f"benchmark={name}", "limit=1", "workers=1", "seed=0",
                                      f"output_dir={tmp_path / 'run'}", "progress=false"]))
    assert results.success_rate == 1.0, results.summary
