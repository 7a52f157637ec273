"""MolmoSpaces' success rules (docs/success_rules.md) at their threshold boundaries, on constructed states."""

from __future__ import annotations

import math
import os

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

os.environ.setdefault("MUJOCO_GL", "egl")

from task_scenes import hold, make_task_env, put_in_receptacle, settle

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.articulated.generate import generate_benchmark as generate_articulated
from molmo_lerobot.content.tabletop.generate import generate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing
from molmo_lerobot.tasks.pick_and_place import tilt


@pytest.fixture
def pnp():
    env, task = make_task_env(generate_benchmark("pick_and_place", 1, 1, 3, "t")[0][0])
    yield env, task
    env.close()


# Receptacle tilt ---------------------------------------------------------------------------------


def test_pure_yaw_of_a_y_up_receptacle_is_no_tilt():
    y_up = Rotation.from_euler("x", 90, degrees=True).as_matrix()  # the body's +y points at the sky
    for yaw in (10.0, 90.0, 179.0):
        now = Rotation.from_euler("z", yaw, degrees=True).as_matrix() @ y_up
        assert tilt(y_up, now) == pytest.approx(0.0, abs=1e-9)
        # the previous rule (angle between the body z axes) called this `yaw` degrees of tilt
        assert math.degrees(math.acos(np.clip(y_up[:, 2] @ now[:, 2], -1, 1))) == pytest.approx(yaw)


@pytest.mark.parametrize("deg", [44.9, 45.1, 59.9, 60.1])
def test_tilt_boundary(deg):
    start = Rotation.from_euler("zyx", [30, 10, 5], degrees=True).as_matrix()
    now = Rotation.from_euler("y", deg, degrees=True).as_matrix() @ start
    assert math.degrees(tilt(start, now)) == pytest.approx(deg, abs=1e-6)


# Boxes (MolmoSpaces' body_aabb) -------------------------------------------------------------------


def test_box_of_a_turned_round_geom_is_its_local_box_turned():
    """A sphere turned 45 degrees about z spans its local cube's diagonal (MolmoSpaces' geom_aabb),
    not its radius; a body with no visible geom is a point at its position."""
    from molmo_lerobot.sim import geometry

    m = mujoco.MjModel.from_xml_string("""<mujoco><worldbody>
      <body name="ball" euler="0 0 45"><geom type="sphere" size="0.03"/></body>
      <body name="ghost" pos="1 2 3"><geom type="box" size="0.1 0.1 0.1" group="3"/></body>
    </worldbody></mujoco>""")
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    _, size = geometry.body_aabb(m, d, m.body("ball").id)
    assert size == pytest.approx([0.06 * math.sqrt(2), 0.06 * math.sqrt(2), 0.06])
    centre, size = geometry.body_aabb(m, d, m.body("ghost").id)
    assert centre == pytest.approx([1, 2, 3]) and size == pytest.approx([0, 0, 0])


# Support ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("angle,ok", [(29.0, True), (31.0, False)])
def test_support_force_within_30_degrees_of_vertical(pnp, angle, ok):
    """A sideways push of tan(angle) x weight, held by friction, tilts the receptacle's net force."""
    env, task = pnp
    put_in_receptacle(env, task)
    body = env.body_id(task.object_name)
    w = env.model.body_subtreemass[body] * 9.81
    env.data.xfrc_applied[body, 0] = w * math.tan(math.radians(angle))
    for _ in range(3):
        env.step(hold(env))
    force = task.support_force()
    measured = math.degrees(math.acos(force[2] / np.linalg.norm(force)))
    assert measured == pytest.approx(angle, abs=0.7)
    assert task.supported_by_force() is ok


def test_contactless_fallback_boundary(pnp):
    """No contact force at all: supported while the object's base is within 1 cm above the receptacle's top."""
    env, task = pnp
    m = env.model
    for g in range(m.ngeom):
        if m.geom_bodyid[g] in task.object_bodies:
            m.geom_contype[g] = m.geom_conaffinity[g] = 0
    from molmo_lerobot.sim import geometry
    r_centre, r_size = geometry.body_aabb(m, env.data, task.receptacle_root)
    top = r_centre[2] + r_size[2] / 2
    o_centre, o_size = geometry.body_aabb(m, env.data, env.body_id(task.object_name))
    offset = env.data.xpos[env.body_id(task.object_name)][2] - (o_centre[2] - o_size[2] / 2)
    quat = env.body_pose(task.object_name)[3:]
    for above, ok in ((0.009, True), (0.011, False)):
        env._place(task.object_name, np.array([r_centre[0], r_centre[1], top + above + offset, *quat]))
        mujoco.mj_forward(m, env.data)
        assert not task.supported_by_force()
        assert task.supported_by_fallback() is ok, above


def test_carry_forward_of_a_supported_pose(pnp, monkeypatch):
    env, task = pnp
    put_in_receptacle(env, task)
    assert task.supported()  # remembers the relative pose
    monkeypatch.setattr(task, "supported_by_force", lambda: False)
    monkeypatch.setattr(task, "supported_by_fallback", lambda: False)
    pose = env.body_pose(task.object_name)
    for dz, ok in ((0.0045, True), (0.0055, False)):
        env._place(task.object_name, pose + np.array([0, 0, dz, 0, 0, 0, 0]))
        mujoco.mj_forward(env.model, env.data)
        assert task.supported() is ok, dz


def test_next_to_counts_any_receptacle_rotation():
    env, task = make_task_env(generate_benchmark("pick_and_place_next_to", 1, 1, 3, "t")[0][0])
    try:
        now = task._pose(env.body_id(task.receptacle_name))
        for deg, ok in ((59.0, True), (61.0, False)):  # next_to_v1's limit: 60°, about the vertical too
            task.start_pose = now.copy()
            task.start_pose[:3, :3] = Rotation.from_euler("z", deg, degrees=True).as_matrix() @ now[:3, :3]
            _, tilted, turned = task.receptacle_displacement()
            assert tilted < 1e-6 and math.degrees(turned) == pytest.approx(deg)
            task.min_gap, task.max_gap = 0.0, 10.0
            monkey = task.supporting_root
            task.supporting_root = lambda body: 1  # the same surface under both
            assert task.success() is ok
            task.supporting_root = monkey
    finally:
        env.close()


@pytest.mark.parametrize("dz,ok", [(0.019, True), (0.021, False)])
def test_next_to_without_a_supporting_contact_falls_back_to_boxes(dz, ok):
    """An object hovering beside the receptacle, no contact under it: it is on the receptacle's surface
    while its box bottom is within 2 cm of the table geom's top (MolmoSpaces' approximate_supporting_geoms)."""
    from molmo_lerobot.sim import geometry

    env, task = make_task_env(generate_benchmark("pick_and_place_next_to", 1, 1, 3, "t")[0][0])
    try:
        settle(env)
        m, d = env.model, env.data
        obj = env.body_id(task.object_name)
        surface = task.supporting_root(obj)
        assert surface is not None and surface == task.supporting_root(task._receptacle)
        top = max(c[2] + s[2] / 2 for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] == surface
                  for c, s in [geometry.aabb(m, d, [g])])
        centre, size = geometry.body_aabb(m, d, obj)
        rise = top + dz - (centre[2] - size[2] / 2)
        env._place(task.object_name, env.body_pose(task.object_name) + np.array([0, 0, rise, 0, 0, 0, 0]))
        mujoco.mj_forward(m, d)
        assert task.supporting_root(obj) is None
        task.min_gap, task.max_gap = 0.0, 10.0
        assert task.success() is ok
    finally:
        env.close()


# Pick ---------------------------------------------------------------------------------------------


def test_pick_lift_is_measured_from_the_episode_start_pose():
    raw = generate_benchmark("pick", 1, 1, 0, "t")[0][0]
    start = list(raw["task"]["pickup_obj_start_pose"])
    start[2] -= 0.02  # the file says it started 2 cm lower than where the scene puts it
    raw["task"]["pickup_obj_start_pose"] = start
    env, task = make_task_env(raw)
    try:
        assert task.lift() == pytest.approx(0.02, abs=0.002)
    finally:
        env.close()


# Open / close -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def articulated():
    return {k: generate_articulated(k, 6, 1, 0, "t")[0] for k in ("open", "close")}


def test_zero_range_joint_is_skipped_by_open_and_never_closed(articulated):
    raw = next(e for e in articulated["open"] if e["task"]["pickup_obj_name"] == "kitchen_hinge_cabinet")
    env, task = make_task_env(raw)
    try:
        m, d = env.model, env.data
        zero, other = task.joints[0], task.joints[1]
        m.jnt_range[zero] = [0.0, 0.0]
        d.qpos[m.jnt_qposadr[zero]] = 0.3  # would be an infinite opening fraction
        lo, hi = m.jnt_range[other]
        end = hi if abs(hi) >= abs(lo) else lo
        for frac, ok in ((0.19, False), (0.21, True)):
            d.qpos[m.jnt_qposadr[other]] = frac * end
            assert task.fraction() == pytest.approx(frac) and task.success() is ok
        task.mode, task.close_joint = "close", zero
        d.qpos[m.jnt_qposadr[zero]] = 0.0
        assert not task.success()  # MolmoSpaces divides by the zero range: never closed
    finally:
        env.close()


def test_any_inst_of_category_counts_every_articulated_object_of_the_category(articulated):
    from molmo_lerobot.tasks.open_close import articulated_joints

    twin = None
    for raw in articulated["open"]:  # a house with a second articulated object (a drawer chest beside)
        name = raw["task"]["pickup_obj_name"]
        env, _ = make_task_env(raw)
        try:
            bodies = {env.model.body(b).name for b in range(env.model.nbody)}
            twin = next((n for n in env.scene_metadata["objects"] if n != name and n in bodies
                         and articulated_joints(env, n)), None)
        finally:
            env.close()
        if twin:
            break
    assert twin, "no generated house has two articulated objects"
    for flag, ok in ((False, False), (True, True)):
        raw2 = {**raw, "task": {**raw["task"], "any_inst_of_category": flag}}
        run = RunContext.build()
        spec = parse_episode(raw2, run.plugins)
        env = build_env(spec, Timing(), run)
        env.reset(0)
        meta = env.scene_metadata
        meta["objects"][twin] = {**meta["objects"].get(twin, {}), "category": meta["objects"][name]["category"]}
        task = Plugins().task_type("open").create(spec, env)
        j = articulated_joints(env, twin)[0]
        lo, hi = env.model.jnt_range[j]
        env.data.qpos[env.model.jnt_qposadr[j]] = 0.5 * (hi if abs(hi) >= abs(lo) else lo)
        try:
            assert task.success() is ok
        finally:
            env.close()


def test_any_inst_of_category_needs_a_category(articulated):
    raw = articulated["open"][0]
    raw = {**raw, "task": {**raw["task"], "any_inst_of_category": True}}
    run = RunContext.build()
    spec = parse_episode(raw, run.plugins)
    env = build_env(spec, Timing(), run)
    env.reset(0)
    env.scene_metadata["objects"].get(raw["task"]["pickup_obj_name"], {}).pop("category", None)
    try:
        with pytest.raises(ValueError, match=r"task.any_inst_of_category: no category"):
            Plugins().task_type("open").create(spec, env)
    finally:
        env.close()
