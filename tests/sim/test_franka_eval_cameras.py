"""MolmoSpaces' eval cameras (camera.eval=true camera.rand_level=L): ranges per level, choice over
recorded cameras, placement that sees the task, redraws, per-episode determinism, run options.
Their own code is compared in tests/parity/test_eval_cameras.py."""

from __future__ import annotations

import copy
import json
import math
import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from droid_variants import droid_episode

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.cameras.franka_eval import (
    FrankaEvalCameraSystem,
    episode_camera_seed,
    exo_ranges,
    wrist_noise,
)
from molmo_lerobot.cameras.options import camera_option_problems, episode_camera_system
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.sim import env as sim_env


def _pick(k: int = 0) -> dict:
    return droid_episode(json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[k])


def _pose(env, name: str) -> np.ndarray:
    c = env.model.camera(name).id
    return np.concatenate([env.data.cam_xpos[c], env.data.cam_xmat[c], [env.model.cam_fovy[c]]])


def test_ranges_per_level():
    assert exo_ranges(0) == exo_ranges(-5)  # the calibrated rig, no noise
    calm = exo_ranges(0)
    assert (calm.azimuth, calm.distance, calm.height, calm.lookat_weight, calm.fov) == \
        ((0, 0), (0, 0), (0, 0), 0.0, (71.0, 71.0))
    assert wrist_noise(0).fov == (0, 0) and wrist_noise(0).rot_deg == (0, 0, 0)
    full = exo_ranges(100)
    assert full == exo_ranges(250)
    assert full.azimuth == pytest.approx((-math.pi, math.pi))  # anywhere around the scene
    assert full.distance == (-0.5, 1.5) and full.height == (-0.3, 0.8) and full.fov == (64.0, 78.0)
    assert full.lookat_noise == (-0.15, 0.15) and full.lookat_weight == 1.0
    mid = exo_ranges(25)  # halfway between the anchors at 10 and 40
    assert mid.azimuth == pytest.approx((-3 * math.pi / 8, 3 * math.pi / 8))
    assert mid.distance == pytest.approx((-0.275, 0.275)) and mid.fov == pytest.approx((67.5, 71.5))
    assert exo_ranges(5).lookat_weight == 0.5  # slerped half-way to looking at the centre
    assert wrist_noise(5).fov == (-2.0, 2.0) and wrist_noise(50) == wrist_noise(10)
    widths = [exo_ranges(lv).distance[1] - exo_ranges(lv).distance[0] for lv in range(0, 101, 5)]
    assert widths == sorted(widths)  # the level only ever widens the draws


def test_eval_cameras_replace_recorded_cameras_and_take_the_level():
    plugins = Plugins()
    raw = _pick(0)
    recorded = parse_episode({**raw, "cameras": json.loads(
        (data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[0]["cameras"]}, plugins)
    assert recorded.cameras
    assert episode_camera_system(recorded, {"system": "droid"}, plugins.camera_system).name == "standard"
    for options in ({"eval": True, "rand_level": 50}, {"system": "FrankaEvalCameraSystem", "rand_level": 50},
                    {"system": "eval", "rand_level": 50}):
        system = episode_camera_system(recorded, options, plugins.camera_system)
        assert (system.name, system.level) == ("FrankaEvalCameraSystem", 50.0)
    assert episode_camera_system(recorded, {"eval": True}, plugins.camera_system).level == 0.0


def test_level_zero_is_the_calibrated_droid_rig_and_level_100_sees_the_task(episode_env):
    raw = _pick(0)
    fixed = episode_env(raw, {})
    calm = episode_env(raw, {"eval": True, "rand_level": 0})
    wild = episode_env(raw, {"eval": True, "rand_level": 100})
    try:
        assert calm.camera_system == "FrankaEvalCameraSystem"
        assert calm.camera_names == ["wrist_camera", "exo_camera_1"]
        assert _pose(calm, "exo_camera_1") == pytest.approx(_pose(fixed, "exo_camera_1"))  # DROID's shoulder
        assert calm.model.cam_fovy[calm.model.camera("wrist_camera").id] == 52.0  # theirs: 52, not 56.74
        assert _pose(calm, "wrist_camera")[:12] == pytest.approx(_pose(fixed, "wrist_camera")[:12])
        target, gripper = raw["task"]["pickup_obj_name"], "robot_0/gripper/base"
        c = wild.model.camera("exo_camera_1").id
        assert not np.allclose(wild.data.cam_xpos[c], calm.data.cam_xpos[c], atol=0.05)
        assert 64.0 <= wild.model.cam_fovy[c] <= 78.0
        seen = wild.visible_fractions("exo_camera_1", [target, gripper])  # a real render of the placed camera
        assert min(seen.values()) >= 1e-4, seen
        for name in wild.camera_names:
            assert wild.render(name).std() > 5
    finally:
        for env in (fixed, calm, wild):
            env.close()


def test_same_episode_same_cameras_in_any_order_and_the_seed_is_theirs(episode_env):
    a, b = _pick(0), _pick(1)
    opts = {"eval": True, "rand_level": 75}
    first = episode_env(a, opts)
    sim_env._MODEL_CACHE.clear()  # as a fresh worker: nothing cached
    other = episode_env(b, opts)
    again = episode_env(copy.deepcopy(a), opts)
    try:
        for name in ("wrist_camera", "exo_camera_1"):
            assert _pose(first, name) == pytest.approx(_pose(again, name))
            assert not np.allclose(_pose(first, name), _pose(other, name))
    finally:
        for env in (first, other, again):
            env.close()
    plugins = Plugins()
    spec = parse_episode(a, plugins)
    # MolmoSpaces' derive_episode_camera_seed: sha256("scene|split|house[|h5|traj][|seed]")[:8 hex digits]
    assert episode_camera_seed(spec) == int(__import__("hashlib").sha256(
        f"procedural_tabletop|val|{a['house_index']}|{a['seed']}".encode()).hexdigest()[:8], 16)
    moved = parse_episode({**a, "language": {"task_description": "something else"}}, plugins)
    assert episode_camera_seed(moved) == episode_camera_seed(spec)  # identity only, as theirs


class _Scene:
    """The reset scene whose first ``hidden`` visibility checks see nothing."""

    def __init__(self, env, hidden: int) -> None:
        self.spec, self.model, self.data, self.robot = env.spec, env.model, env.data, env.robot
        self.hidden, self.draws = hidden, []

    def visible_fractions(self, camera, bodies):
        self.draws.append(self.model.cam_pos[self.model.camera(camera).id].copy())
        return {b: (0.0 if len(self.draws) <= self.hidden else 0.5) for b in bodies}


def test_an_occluded_draw_is_drawn_again_and_fifty_hopeless_ones_fail_the_episode(episode_env):
    env = episode_env(_pick(0), {"eval": True, "rand_level": 100})
    try:
        system = FrankaEvalCameraSystem(100)
        scene = _Scene(env, hidden=2)
        poses = system.place(scene)
        assert len(scene.draws) == 3 and not np.allclose(scene.draws[0], scene.draws[2])
        assert poses["exo_camera_1"][0] == pytest.approx(scene.draws[2])  # the first draw that sees the task
        with pytest.raises(ValueError, match=r"FrankaEvalCameraSystem at level 100: no placement of exo_camera_1 "
                                             r"in 50 draws sees all of \['builtin_grey_can', 'robot_0/gripper/base'\]"):
            system.place(_Scene(env, hidden=10_000))
    finally:
        env.close()


@pytest.mark.parametrize(("camera", "problem"), [
    ({"eval": True, "rand_level": 150}, "camera.rand_level: expected a number in 0-100"),
    ({"eval": "yes"}, "camera.eval: expected true or false"),
    ({"rand_level": 50}, "camera.rand_level applies to MolmoSpaces' eval cameras: add camera.eval=true"),
    ({"eval": True, "system": "droid"}, "conflicts with camera.system=droid"),
    ({"eval": True, "randomization": 2}, "camera.randomization jitters the episode's recorded cameras"),
    ({"system": "FrankaEvalCameraSystem", "overrides": {"exo": {"fov": 60}}}, "camera.overrides edits"),
])
def test_bad_camera_options_stop_the_run(camera, problem):
    assert any(problem in p for p in camera_option_problems(camera)), camera_option_problems(camera)


def test_good_camera_options_compose():
    from molmo_lerobot.config import compose
    from molmo_lerobot.run_config import config_problems

    cfg = compose(["camera.eval=true", "camera.rand_level=50"])
    assert cfg.camera.eval is True and cfg.camera.rand_level == 50
    from omegaconf import OmegaConf

    assert config_problems(OmegaConf.to_container(cfg, resolve=True)) == []
    assert camera_option_problems({"system": "eval", "rand_level": 12.5}) == []


def test_a_run_with_eval_cameras(tmp_path, fork_servers):
    """molmo-eval camera.eval=true camera.rand_level=50 (MolmoSpaces' --use_eval_cameras
    --camera_rand_level 50): the workers build the eval cameras; the run records the options."""
    from molmo_lerobot.config import compose
    from molmo_lerobot.runner.evaluate import run_evaluation

    bench = tmp_path / "droid_pick"
    bench.mkdir()
    (bench / "benchmark.json").write_text(json.dumps([_pick(0)]))
    cfg = compose(["policy=scripted", f"benchmark.path={bench}", "workers=1", "horizon=3", "progress=false",
                   f"output_dir={tmp_path / 'run'}", "camera.eval=true", "camera.rand_level=50"])
    res = run_evaluation(cfg, fork_servers)
    assert res.summary["n_errors"] == 0
    assert [e.extra["camera_system"] for e in res.episodes] == ["FrankaEvalCameraSystem"]
    run = json.loads((tmp_path / "run" / "results.json").read_text())
    assert run["eval_options"]["camera"]["eval"] is True and run["eval_options"]["camera"]["rand_level"] == 50


def test_eval_cameras_render_at_their_resolution():
    """Their eval system renders 640 x 368 whatever the episode says (the camera.eval override)."""
    spec = parse_episode(_pick(0), Plugins())
    assert list(spec.img_resolution) == [224, 224]
    for camera in ({"eval": True, "rand_level": 30}, {"system": "FrankaEvalCameraSystem"}):
        run = RunContext.build({"camera": camera})
        assert list(run.plugins.apply_episode_overrides(spec, run).img_resolution) == [640, 368]
    run = RunContext.build({"camera": {"system": "droid"}})
    assert run.plugins.apply_episode_overrides(spec, run) == spec


@pytest.mark.slow
def test_eval_cameras_are_the_same_for_any_worker_count(tmp_path):
    """Each episode's eval cameras come from its own identity: one worker or two, the same
    frames (the per-episode thumbnails, first and last exterior frame, compared byte for byte)."""
    from molmo_lerobot.config import compose
    from molmo_lerobot.runner.evaluate import run_evaluation

    bench = tmp_path / "droid_pick"
    bench.mkdir()
    (bench / "benchmark.json").write_text(json.dumps([_pick(k) for k in range(3)]))
    shots = {}
    for workers in (1, 2):
        out = tmp_path / f"run{workers}"
        run_evaluation(compose(["policy=scripted", f"benchmark.path={bench}", f"workers={workers}", "horizon=2",
                                "progress=false", f"output_dir={out}", "camera.eval=true", "camera.rand_level=100"]))
        shots[workers] = {p.name: p.read_bytes() for p in sorted((out / "thumbnails").iterdir())}
    assert len(shots[1]) == 3 and shots[1] == shots[2]
