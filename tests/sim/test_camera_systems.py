"""Camera systems are chosen per episode; DROID placements; randomized ones reproducible; no debug geometry."""

from __future__ import annotations

import copy
import json
import os

import mujoco
import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from droid_variants import droid_episode

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.cameras.base import choose_camera_system
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins


def _pick(k: int = 0) -> dict:
    return json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[k]


def _cam_pose(env, name: str) -> np.ndarray:
    c = env.model.camera(name).id
    return np.concatenate([env.data.cam_xpos[c], env.data.cam_xmat[c], [env.model.cam_fovy[c]]])


def test_choice_order():
    plugins = Plugins()
    spec = parse_episode(droid_episode(_pick()), plugins)
    assert choose_camera_system(spec, None, "FrankaDroidCameraSystem") == "FrankaDroidCameraSystem"
    with_source = parse_episode({**droid_episode(_pick()), "source": {
        "h5_file": "x", "traj_key": "t", "camera_system_class": "FrankaRandomizedDroidCameraSystem"}}, plugins)
    assert choose_camera_system(with_source, None, "FrankaDroidCameraSystem") == "FrankaRandomizedDroidCameraSystem"
    assert choose_camera_system(with_source, "droid", "FrankaDroidCameraSystem") == "droid"
    own = parse_episode(_pick(), plugins)
    assert choose_camera_system(own, "droid", None) == "standard"  # the episode's cameras come first


def test_plugins_and_aliases():
    plugins = Plugins()
    assert plugins.camera_system("droid") is plugins.camera_system("FrankaDroidCameraSystem")
    assert plugins.camera_system("droid_randomized") is plugins.camera_system("FrankaRandomizedDroidCameraSystem")


def test_empty_cameras_run_with_the_droid_system(episode_env):
    env = episode_env(droid_episode(_pick()))
    try:
        assert env.camera_system == "FrankaDroidCameraSystem"
        assert env.camera_names == ["wrist_camera", "exo_camera_1"]  # MolmoSpaces' FrankaDroidCameraSystem
        m = env.model
        assert m.cam_bodyid[m.camera("wrist_camera").id] == m.body("robot_0/gripper/base").id
        assert m.cam_bodyid[m.camera("exo_camera_1").id] == m.body("robot_0/fr3_link0").id
        assert m.cam_fovy[m.camera("exo_camera_1").id] == pytest.approx(71.0)
        assert m.cam_pos[m.camera("exo_camera_1").id] == pytest.approx([0.1, 0.57, 0.66])
        for name in env.camera_names:
            assert env.render(name).std() > 5  # not a blank image
    finally:
        env.close()


EXO = ("exo_camera_1", "exo_camera_2", "exo_camera_3")


def test_randomized_placement_is_reproducible_per_episode(episode_env):
    a, b = droid_episode(_pick(0)), droid_episode(_pick(1))
    e1, e2, e3 = (episode_env(a, {"system": "FrankaRandomizedDroidCameraSystem"}),
                  episode_env(copy.deepcopy(a), {"system": "droid_randomized"}),
                  episode_env(b, {"system": "FrankaRandomizedDroidCameraSystem"}))
    try:
        assert e1.camera_names == ["wrist_camera", *EXO]
        fixed = episode_env(a)
        for name in ("wrist_camera", *EXO):
            assert _cam_pose(e1, name) == pytest.approx(_cam_pose(e2, name))  # same episode, same cameras
            assert not np.allclose(_cam_pose(e1, name), _cam_pose(e3, name))  # another episode, others
        assert not np.allclose(_cam_pose(e1, "wrist_camera"), _cam_pose(fixed, "wrist_camera"))
        fixed.close()
        target = a["task"]["pickup_obj_name"]
        gripper = "robot_0/gripper/base"
        centre = (e1.body_pose(target)[:3] + e1.data.site_xpos[e1.robot.tcp_site]) / 2  # objects + TCP
        for name, fov, (near, far) in zip(EXO, (72, 72, 140), ((0.2, 0.8), (0.2, 0.8), (0.2, 0.5)), strict=True):
            c = e1.model.camera(name).id
            pos, rot = e1.data.cam_xpos[c], e1.data.cam_xmat[c].reshape(3, 3)
            to_centre = (centre - pos) / np.linalg.norm(centre - pos)
            assert -rot[:, 2] @ to_centre > np.cos(np.radians(15))  # it looks at the workspace centre
            assert near <= np.linalg.norm((pos - centre)[:2]) <= far
            assert fov - 8 <= e1.model.cam_fovy[c] <= fov
            seen = e1.visible_fractions(name, [target, gripper])
            assert min(seen.values()) >= 1e-4, (name, seen)  # the target and the gripper are in view
    finally:
        for e in (e1, e2, e3):
            e.close()


class _Scene:
    """A stand-in for the reset scene: the first ``hidden`` draws see nothing."""

    def __init__(self, env, hidden: int) -> None:
        self.spec, self.model, self.data, self.robot = env.spec, env.model, env.data, env.robot
        self.body_id, self.hidden, self.draws = env.body_id, hidden, []

    def visible_fractions(self, camera, bodies):
        self.draws.append((camera, self.model.cam_pos[self.model.camera(camera).id].copy()))
        return {b: (0.0 if len(self.draws) <= self.hidden else 0.5) for b in bodies}


def test_an_occluded_draw_is_drawn_again_and_a_hopeless_one_fails_the_episode(episode_env):
    from molmo_lerobot.cameras.droid import FrankaRandomizedDroidCameraSystem

    system = FrankaRandomizedDroidCameraSystem()
    env = episode_env(droid_episode(_pick(0)), {"system": "FrankaRandomizedDroidCameraSystem"})
    try:
        scene = _Scene(env, hidden=3)
        poses = system.place(scene)
        assert [c for c, _ in scene.draws[:5]] == ["exo_camera_1"] * 4 + ["exo_camera_2"]
        assert poses["exo_camera_1"][0] == pytest.approx(scene.draws[3][1])  # the fourth draw, the first seen
        assert not np.allclose(scene.draws[0][1], scene.draws[3][1])
        with pytest.raises(ValueError, match="no placement of exo_camera_1 in 100 draws sees all of"):
            system.place(_Scene(env, hidden=10_000))
    finally:
        env.close()


def test_no_debug_geometry_in_camera_images(episode_env):
    """The Panda model's `end_effector` site (site group 0) used to show as a grey ball in every wrist
    frame. Cameras render only geoms of groups 0-2: images equal a render with every site removed."""
    raw = _pick(0)
    env = episode_env(raw)
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
