"""A nav episode as MolmoSpaces' generators write it (legacy ``house_*/episode_*.json`` layout, their
``task_cls``, ``init_qpos["base"] = [0, 0, 0]``, two-driver gripper state, a robot-mounted head camera,
no ``task_horizon_sec``) validates and runs on a nav_houses scene; broken copies fail naming the file,
the episode and the field."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from molmo_lerobot.benchmark.load import BenchmarkError, load_benchmark
from molmo_lerobot.benchmark.validate import validate_benchmark
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.scripted_nav import ScriptedNav
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing

DATA = Path(__file__).resolve().parents[1] / "data" / "molmospaces" / "nav_legacy"
FILE = "house_290/episode_00000000.json"


def test_their_nav_episode_validates_and_builds(run):
    bench = load_benchmark(DATA, run.plugins)
    assert validate_benchmark(bench, run.plugins, run) == []
    (spec,) = bench.episodes
    task_type = run.plugins.task_type(spec.task_name)
    assert task_type.name == "nav_to_obj" and task_type.default_horizon_sec == 100.0  # their 500 × 200 ms
    env = build_env(spec, Timing(), run, {})
    try:
        env.reset(0)
        assert env.camera_system == "standard" and env.camera_names == ["head_camera"]
        obs = env.observe(images=False)
        assert obs["qpos"]["base"][:2].tolist() == spec.task.robot_base_pose[:2]  # not their init_qpos [0, 0, 0]
        assert obs["qpos"]["gripper"][0] < 0.01  # their two open driver angles
        task = task_type.create(spec, env)
        task.setup()
        assert task.targets == spec.task.pickup_obj_candidates and not task.success()
    finally:
        env.close()


@pytest.mark.slow
def test_their_nav_episode_runs_to_success_with_the_expert(run):
    (spec,) = load_benchmark(DATA, run.plugins).episodes
    env = build_env(spec, Timing(), run, {})
    try:
        env.reset(0)
        task = run.plugins.task_type(spec.task_name).create(spec, env)
        task.setup()
        expert = ScriptedNav({})
        expert.reset(EpisodeContext(spec=spec, episode_index=0, seed=0, prompt=spec.prompt,
                                    move_groups=env.move_groups, policy_dt_s=0.066, env=env, catalog=run.catalog))
        success = False
        for _ in range(len(expert.plan) // expert.chunk + 2):
            chunk = expert.act({})
            for k in range(expert.chunk):
                env.step({g: chunk[g][k] for g in chunk})
            if task.success():
                success = True
                break
        assert success and task.nearest()[1] < 1.5
    finally:
        env.close()


@pytest.mark.parametrize(("edit", "field"), [
    (lambda t: t.update(succ_pos_threshold=-1.0), "task.succ_pos_threshold"),
    (lambda t: t.pop("pickup_obj_name"), "task.pickup_obj_name"),
    (lambda t: t.update(pickup_obj_candidates="libero_orange_juice"), "task.pickup_obj_candidates"),
])
def test_schema_errors_name_file_episode_and_field(run, tmp_path, edit, field):
    root = tmp_path / "bench"
    shutil.copytree(DATA, root)
    path = root / FILE
    raw = json.loads(path.read_text())
    edit(raw["task"])
    path.write_text(json.dumps(raw))
    with pytest.raises(BenchmarkError) as err:
        load_benchmark(root, run.plugins)
    (problem,) = err.value.problems
    assert problem.field == field and problem.file.endswith(FILE) and problem.episode_index == 0
    assert FILE in str(err.value) and field in str(err.value)


def test_a_candidate_missing_from_the_scene_fails_the_episode_naming_the_field(run, tmp_path):
    root = tmp_path / "bench"
    shutil.copytree(DATA, root)
    path = root / FILE
    raw = json.loads(path.read_text())
    raw["cameras"] = []  # the robot's camera system then builds head_camera
    raw["task"]["pickup_obj_candidates"] = ["television_9a8e_1_0_0"]
    path.write_text(json.dumps(raw))
    (spec,) = load_benchmark(root, run.plugins).episodes
    env = build_env(spec, Timing(), run, {})
    try:
        env.reset(0)
        assert env.camera_names == ["head_camera", "wrist_camera"]
        with pytest.raises(ValueError, match=r"task\.pickup_obj_candidates: none of \['television_9a8e_1_0_0'\]"):
            run.plugins.task_type(spec.task_name).create(spec, env)
    finally:
        env.close()
