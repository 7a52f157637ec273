"""The pick-and-place family's success rules on constructed simulator states."""

from __future__ import annotations

import copy
import math
import os

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

os.environ.setdefault("MUJOCO_GL", "egl")

from task_scenes import make_task_env, put_in_receptacle, settle

from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, BUILTIN_RECEPTACLES
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.tabletop.generate import generate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.robots.franka import FINGER_TRAVEL
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim import geometry
from molmo_lerobot.sim.env import Timing


def _episode(task: str, seed: int = 3) -> dict:
    return generate_benchmark(task, 1, 1, seed, "test")[0][0]


@pytest.fixture
def pnp():
    env, task = make_task_env(_episode("pick_and_place"))
    yield env, task
    env.close()


@pytest.fixture
def next_to():
    env, task = make_task_env(_episode("pick_and_place_next_to"))
    yield env, task
    env.close()


def _clear_table(env, keep: set[str]) -> None:
    """Move every other object and receptacle onto the floor, far from the table."""
    names = [n for n in {**BUILTIN_OBJECTS, **BUILTIN_RECEPTACLES} if n not in keep
             and mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_BODY, n) >= 0]
    for k, name in enumerate(names):
        env._place(name, np.array([-1.0 - 0.3 * k, 1.5, 0.2, 1, 0, 0, 0]))
    mujoco.mj_forward(env.model, env.data)


def test_start_state_is_not_success(pnp, next_to):
    for env, task in (pnp, next_to):
        settle(env, 2)
        assert not task.success() and task.reward() == 0.0
        assert task.support_fraction() == 0.0
        assert task.support_fraction(env.subtree_bodies("table")) == pytest.approx(1.0, abs=0.02)
    assert next_to[1].gap() > 0.1  # generated next-to episodes start well apart


def test_resting_in_the_receptacle_succeeds(pnp):
    env, task = pnp
    put_in_receptacle(env, task)
    assert task.support_fraction() == pytest.approx(1.0, abs=0.02)
    assert not task.robot_touching() and task.success() and task.reward() == 1.0


@pytest.mark.parametrize("lift,ok", [(0.45, True), (0.55, False)])
def test_support_fraction_threshold(pnp, lift, ok):
    """An upward push of ``lift`` x weight on the object leaves 1 - lift for the receptacle to carry:
    the force rule fails past half, and MolmoSpaces' fallback (contact below the object's centre
    with a near-vertical normal) still calls it supported."""
    env, task = pnp
    put_in_receptacle(env, task)
    body = env.body_id(task.object_name)
    env.data.xfrc_applied[body, 2] = lift * env.model.body_subtreemass[body] * 9.81
    settle(env, 4)
    assert task.support_fraction() == pytest.approx(1.0 - lift, abs=0.02)
    assert task.supported_by_force() is ok
    assert task.supported_by_fallback() and task.success()


def test_robot_still_touching_fails(pnp):
    env, task = pnp
    _clear_table(env, {task.object_name, task.receptacle_name})
    site = env.robot.tcp_site
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, env.data.site_xmat[site])
    env._place(task.object_name, np.concatenate([env.data.site_xpos[site], quat]))
    width = 2 * BUILTIN_OBJECTS[task.object_name].half_extents[1]
    env.robot.set_qpos(env.data, "gripper", [1.0 - (width / 2 - 0.002) / FINGER_TRAVEL])
    mujoco.mj_forward(env.model, env.data)
    bottom = env.data.xpos[env.body_id(task.object_name)][2] - BUILTIN_OBJECTS[task.object_name].half_extents[2]
    # the receptacle's floor right under the held object (1 mm overlap), so both touch it
    rec = BUILTIN_RECEPTACLES[task.receptacle_name]
    pos = env.data.xpos[env.body_id(task.object_name)]
    env._place(task.receptacle_name, np.array([pos[0], pos[1], bottom + 0.001 + rec.half_extents[2]
                                               - 2 * rec.base_half_height, 1, 0, 0, 0]))
    mujoco.mj_forward(env.model, env.data)
    task.start_pose = task._pose(env.body_id(task.receptacle_name))  # the receptacle counts as unmoved
    assert task.robot_touching() and task.support_fraction() >= 0.5 and task.receptacle_in_place()
    assert not task.success()


def _turned(pose: np.ndarray, axis: np.ndarray, deg: float) -> np.ndarray:
    out = pose.copy()
    out[:3, :3] = Rotation.from_rotvec(np.radians(deg) * axis).as_matrix() @ pose[:3, :3]
    return out


def test_receptacle_displacement_limits(pnp):
    env, task = pnp
    put_in_receptacle(env, task)
    now = task._pose(env.body_id(task.receptacle_name))
    assert task.max_pos == 0.15 and task.max_rot == pytest.approx(math.radians(60), abs=1e-4)  # pick_and_place_v1's
    for shift, ok in (([0.14, 0, 0], True), ([0, 0.16, 0], False)):
        task.start_pose = now.copy()
        task.start_pose[:3, 3] -= shift
        assert task.success() is ok
    for deg, ok in ((59.0, True), (61.0, False)):
        task.start_pose = _turned(now, np.array([1.0, 0.0, 0.0]), deg)
        assert task.success() is ok, deg


def test_yaw_is_ignored(pnp):
    env, task = pnp
    put_in_receptacle(env, task)
    task.setup()
    now = task._pose(env.body_id(task.receptacle_name))
    task.start_pose = _turned(now, np.array([0.0, 0.0, 1.0]), 170.0)  # turned 170° about the vertical
    moved, tilted, turned = task.receptacle_displacement()
    assert moved < 1e-9 and tilted < 1e-6 and turned == pytest.approx(math.radians(170)) and task.success()


def test_polygon_gap():
    square = geometry.polygon(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float))
    shifted = geometry.polygon(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float) + np.array([1.25, 0.0]))
    assert geometry.gap(square, geometry.polygon(np.array([[0.5, 0.5], [1.5, 0.5], [1.5, 1.5]]))) == 0.0
    assert geometry.gap(square, shifted) == pytest.approx(0.25)
    a = (np.zeros(3), np.ones(3))
    assert geometry.aabb_xy_gap(a, (np.array([2.0, 2.0, 0.0]), np.ones(3))) == pytest.approx(math.sqrt(2))


def _beside(env, task, gap: float) -> float:
    """Put the object on the table beside the receptacle with XY surface gap ``gap``; return the settled gap."""
    rec = env.body_pose(task.receptacle_name)
    obj = env.body_pose(task.object_name)
    direction = np.array([0.0, -1.0 if rec[1] > 0 else 1.0])  # towards the table's middle
    dist = 0.15
    for _ in range(5):
        env._place(task.object_name, np.array([*(rec[:2] + dist * direction), obj[2], *obj[3:]]))
        mujoco.mj_forward(env.model, env.data)
        dist += gap - task.gap()
    settle(env, 3)
    return task.gap()


@pytest.mark.parametrize("gap,ok", [(0.055, True), (0.066, False), (0.0, True)])
def test_next_to_gap(next_to, gap, ok):
    env, task = next_to
    _clear_table(env, {task.object_name, task.receptacle_name})
    measured = _beside(env, task, gap)
    assert measured == pytest.approx(gap, abs=0.002)
    assert task.success() is ok


def test_next_to_gap_bounds_and_tolerance(next_to):
    env, task = next_to
    _clear_table(env, {task.object_name, task.receptacle_name})
    g = _beside(env, task, 0.03)
    assert task.success()
    task.max_gap = g - 0.01 + 0.0005  # max + 0.01 tolerance just above the gap
    assert task.success()
    task.max_gap = g - 0.01 - 0.0005
    assert not task.success()
    task.max_gap, task.min_gap = 0.05, g + 0.0005
    assert not task.success()


def test_next_to_inside_the_receptacle_fails(next_to):
    env, task = next_to
    put_in_receptacle(env, task)
    assert task.gap() == 0.0 and not task.success()  # supported by the receptacle, not the table


def test_thresholds_defaults_and_overrides():
    plugins = Plugins()
    raw = _episode("pick_and_place_next_to")
    tt = plugins.task_type("pick_and_place_next_to")
    assert plugins.task_type("molmo_spaces.tasks.pick_and_place_next_to_task.PickAndPlaceNextToTask") is tt
    assert plugins.task_type(raw["task"]["task_cls"]) is tt and tt.default_horizon_sec == 40.0
    stripped = copy.deepcopy(raw)
    for field in ("receptacle_supported_weight_frac", "max_place_receptacle_pos_displacement",
                  "max_place_receptacle_rot_displacement", "min_surface_to_surface_gap"):
        del stripped["task"][field]
    stripped["task"]["max_surface_to_surface_gap"] = None  # null means the default
    assert tt.thresholds(parse_episode(stripped, plugins)) == {
        "receptacle_supported_weight_frac": 0.5, "max_place_receptacle_pos_displacement": 0.15,
        "max_place_receptacle_rot_displacement": pytest.approx(math.radians(60)),
        "min_surface_to_surface_gap": 0.0, "max_surface_to_surface_gap": 0.05, "surface_gap_tolerance": 0.01}
    raw["task"]["receptacle_supported_weight_frac"] = 0.8
    assert tt.thresholds(parse_episode(raw, plugins))["receptacle_supported_weight_frac"] == 0.8
    for name in ("pick_and_place", "pick_and_place_color"):
        assert plugins.task_type(name).default_horizon_sec == 40.0


def test_color_task_paints_and_needs_the_named_receptacle():
    raw = _episode("pick_and_place_color")
    colors = raw["task"]["object_colors"]
    assert len(colors) == 2 and len({tuple(c) for c in colors.values()}) == 2
    env, task = make_task_env(raw)
    try:
        m = env.model
        for name, rgba in colors.items():
            geoms = geometry.body_geoms(m, env.subtree_bodies(name))  # the visible ones
            assert geoms and all(np.allclose(m.geom_rgba[g], rgba) and m.geom_matid[g] == -1 for g in geoms)
        run = RunContext.build()
        spec = parse_episode(raw, run.plugins)
        fresh = build_env(spec, Timing(), run)  # same cached model: the paint must not leak
        g0 = geometry.body_geoms(m, env.subtree_bodies(task.receptacle_name))[0]
        assert not np.allclose(fresh.model.geom_rgba[g0], colors[task.receptacle_name])
        fresh.close()
        other = raw["task"]["other_receptacle_names"][0]
        task.receptacle_name, keep = other, task.receptacle_name
        put_in_receptacle(env, task)  # into the other colour's receptacle
        task.receptacle_name = keep
        assert not task.success()
    finally:
        env.close()


def test_bad_receptacle_is_named():
    raw = _episode("pick_and_place")
    raw["task"]["place_receptacle_name"] = "unicorn"
    run = RunContext.build()
    spec = parse_episode(raw, run.plugins)
    env = build_env(spec, Timing(), run)
    try:
        env.reset(0)
        with pytest.raises(ValueError, match=r"task.place_receptacle_name: no body 'unicorn'"):
            Plugins().task_type("pick_and_place").create(spec, env)
    finally:
        env.close()
