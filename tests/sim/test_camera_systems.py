"""Camera systems are chosen per episode; DROID placements; randomized ones reproducible; no debug geometry."""

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

from molmo_lerobot.benchmark.schema import EpisodeSpec  # noqa: E402
from molmo_lerobot.cameras.base import choose_camera_system  # noqa: E402
from molmo_lerobot.paths import data_path  # noqa: E402
from molmo_lerobot.plugins import get_plugins  # noqa: E402
from molmo_lerobot.runner.episode_env import build_env  # noqa: E402
from molmo_lerobot.sim.env import Timing  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tasks"))
from droid_variants import droid_episode  # noqa: E402


def _pick(k: int = 0) -> dict:
    return json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[k]


def _env(raw: dict, system: str | None = None):
    env = build_env(EpisodeSpec.model_validate(raw), Timing(), get_plugins(), system)
    env.reset(0)
    return env


def _cam_pose(env, name: str) -> np.ndarray:
    c = env.model.camera(name).id
    return np.concatenate([env.data.cam_xpos[c], env.data.cam_xmat[c], [env.model.cam_fovy[c]]])


def test_choice_order():
    spec = EpisodeSpec.model_validate(droid_episode(_pick()))
    assert choose_camera_system(spec, None, "FrankaDroidCameraSystem") == "FrankaDroidCameraSystem"
    with_source = EpisodeSpec.model_validate({**droid_episode(_pick()), "source": {
        "h5_file": "x", "traj_key": "t", "camera_system_class": "FrankaRandomizedDroidCameraSystem"}})
    assert choose_camera_system(with_source, None, "FrankaDroidCameraSystem") == "FrankaRandomizedDroidCameraSystem"
    assert choose_camera_system(with_source, "droid", "FrankaDroidCameraSystem") == "droid"
    own = EpisodeSpec.model_validate(_pick())
    assert choose_camera_system(own, "droid", None) == "standard"  # the episode's cameras come first


def test_plugins_and_aliases():
    plugins = get_plugins()
    assert plugins.camera_system("droid") is plugins.camera_system("FrankaDroidCameraSystem")
    assert plugins.camera_system("droid_randomized") is plugins.camera_system("FrankaRandomizedDroidCameraSystem")


def test_empty_cameras_run_with_the_droid_system():
    env = _env(droid_episode(_pick()))
    try:
        assert env.camera_system == "FrankaDroidCameraSystem"
        assert env.camera_names == ["wrist_camera", "exo_camera_1", "exo_camera_2"]
        m = env.model
        assert m.cam_bodyid[m.camera("wrist_camera").id] == m.body("robot_0/gripper/base").id
        assert m.cam_bodyid[m.camera("exo_camera_1").id] == m.body("robot_0/fr3_link0").id
        assert m.cam_fovy[m.camera("exo_camera_1").id] == pytest.approx(71.0)
        assert m.cam_pos[m.camera("exo_camera_1").id] == pytest.approx([0.1, 0.57, 0.66])
        assert m.cam_pos[m.camera("exo_camera_2").id] == pytest.approx([0.1, -0.57, 0.66])
        for name in env.camera_names:
            assert env.render(name).std() > 5  # not a blank image
    finally:
        env.close()


def test_randomized_placement_is_reproducible_per_episode():
    a, b = droid_episode(_pick(0)), droid_episode(_pick(1))
    e1, e2, e3 = _env(a, "FrankaRandomizedDroidCameraSystem"), _env(copy.deepcopy(a), "droid_randomized"), \
        _env(b, "FrankaRandomizedDroidCameraSystem")
    try:
        fixed = _env(a)
        for name in ("wrist_camera", "exo_camera_1", "exo_camera_2"):
            assert _cam_pose(e1, name) == pytest.approx(_cam_pose(e2, name))  # same episode, same cameras
            assert not np.allclose(_cam_pose(e1, name), _cam_pose(e3, name))  # another episode, others
        assert not np.allclose(_cam_pose(e1, "wrist_camera"), _cam_pose(fixed, "wrist_camera"))
        fixed.close()
        target = np.asarray(a["scene_modifications"]["object_poses"][a["task"]["pickup_obj_name"]][:3])
        for name in ("exo_camera_1", "exo_camera_2"):
            c = e1.model.camera(name).id
            pos, rot = e1.data.cam_xpos[c], e1.data.cam_xmat[c].reshape(3, 3)
            to_target = (target - pos) / np.linalg.norm(target - pos)
            assert -rot[:, 2] @ to_target > np.cos(np.radians(15))  # it looks at the workspace centre
            assert 0.05 <= pos[2] - target[2] <= 0.6 + 0.1
    finally:
        for e in (e1, e2, e3):
            e.close()


def test_no_debug_geometry_in_camera_images():
    """The Panda model's `end_effector` site (site group 0) used to show as a grey ball in every wrist
    frame. Cameras render only geoms of groups 0-2: images equal a render with every site removed."""
    raw = _pick(0)
    env = _env(raw)
    try:
        m, d = env.model, env.data
        site = m.site("robot/end_effector").id
        assert m.site_group[site] == 0
        shown = env.render("wrist")
        with mujoco.Renderer(m, height=shown.shape[0], width=shown.shape[1]) as default:
            default.update_scene(d, camera="wrist")  # MuJoCo's default options draw group-0 sites
            with_sites = default.render()
        assert np.abs(with_sites.astype(int) - shown.astype(int)).max() > 50
        m.site_rgba[:, 3] = 0.0  # no sites at all
        with mujoco.Renderer(m, height=shown.shape[0], width=shown.shape[1]) as clean:
            clean.update_scene(d, camera="wrist", scene_option=env.camera_view_options())
            assert np.array_equal(clean.render(), shown)
    finally:
        env.close()
