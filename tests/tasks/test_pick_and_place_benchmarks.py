"""Receptacles, houses holding them, and the generated pick-and-place family benchmarks."""

from __future__ import annotations

import json
import math

import mujoco
import pytest

from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, BUILTIN_RECEPTACLES, PAINT_COLORS
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.tabletop.generate import (
    NEXT_TO_START_GAP,
    _receptacle_footprint,
    _resting,
    generate_benchmark,
)
from molmo_lerobot.content.tabletop.scene import ProceduralTabletop, ProceduralTabletopReceptacles
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins

SHIPPED = {"pick_and_place_v1": "pick_and_place", "next_to_v1": "pick_and_place_next_to",
           "color_v1": "pick_and_place_color"}


@pytest.mark.parametrize("rec", list(BUILTIN_RECEPTACLES.values()), ids=list(BUILTIN_RECEPTACLES))
def test_receptacle_compiles_with_its_mass_and_footprint(rec):
    model = mujoco.MjModel.from_xml_string(rec.mjcf())
    body = model.body(rec.uid)
    assert model.body_subtreemass[body.id] == pytest.approx(rec.mass)
    assert model.body_geomnum[body.id] == len(rec.geoms()) >= 5
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    hx, hy, hz = rec.half_extents
    for g in range(model.ngeom):  # every geom inside the declared bounding box
        half_height = model.geom_size[g][1 if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CYLINDER else 2]
        assert abs(data.geom_xpos[g][2]) + half_height <= hz + 1e-9
        assert max(abs(data.geom_xpos[g][0]), abs(data.geom_xpos[g][1])) <= max(hx, hy)
    assert rec.metadata()["receptacle"] and rec.uid not in BUILTIN_OBJECTS


def test_houses_hold_receptacles_outside_the_workspace():
    scene = ProceduralTabletopReceptacles()
    for house in (0, 7, 150):
        plain = ProceduralTabletop().metadata(house)["objects"]
        assert not any(o["receptacle"] for o in plain.values())  # pick_v1's scenes stay as they were
        assert set(plain) < set(scene.metadata(house)["objects"])
        meta = scene.metadata(house)
        recs = [o for o in meta["objects"].values() if o["receptacle"]]
        assert len(recs) == 3 and recs[0]["category"] == recs[1]["category"] != recs[2]["category"]
        assert recs[0]["color"] != recs[1]["color"]
        for o in recs:
            assert abs(o["default_pose"][1]) - BUILTIN_RECEPTACLES[o["asset_id"]].half_extents[1] > 0.3
        model = scene.build(house).compile()
        for o in recs:
            assert model.body(o["asset_id"]).jntnum == 1  # a free body


@pytest.mark.parametrize("task", list(SHIPPED.values()))
def test_generation_is_deterministic_and_valid(task):
    a = generate_benchmark(task, 2, 3, 4, "x")
    assert json.dumps(a) == json.dumps(generate_benchmark(task, 2, 3, 4, "x"))
    plugins = Plugins()
    for raw in a[0]:
        spec = parse_episode(raw, plugins)
        t = spec.task
        poses = spec.scene_modifications.object_poses
        assert t.pickup_obj_name in poses and t.place_receptacle_name in poses
        assert spec.task.task_horizon_sec == 40.0 and spec.task_name == raw["task"]["task_cls"]
        pick, rec = BUILTIN_OBJECTS[t.pickup_obj_name], BUILTIN_RECEPTACLES[t.place_receptacle_name]
        assert f"the {pick.color} {pick.category}" in spec.prompt and rec.category in spec.prompt
        assert sum(n in BUILTIN_OBJECTS for n in poses) >= 4  # the object and its distractors


def test_next_to_episodes_start_apart():
    for raw in generate_benchmark("pick_and_place_next_to", 3, 3, 1, "x")[0]:
        t = raw["task"]
        a, b = raw["scene_modifications"]["object_poses"][t["pickup_obj_name"]], t["place_receptacle_start_pose"]
        r_rec = _receptacle_footprint(BUILTIN_RECEPTACLES[t["place_receptacle_name"]], 0.0)[1]
        r_obj = _resting(BUILTIN_OBJECTS[t["pickup_obj_name"]], 0.0)[1]
        assert math.dist(a[:2], b[:2]) >= r_rec + r_obj + NEXT_TO_START_GAP
        assert raw["language"]["task_description"].startswith(f"put the {BUILTIN_OBJECTS[t['pickup_obj_name']].color}")


def test_color_episodes_tell_receptacles_apart_by_paint_only():
    for raw in generate_benchmark("pick_and_place_color", 3, 3, 2, "x")[0]:
        t = raw["task"]
        target, other = t["place_receptacle_name"], t["other_receptacle_names"][0]
        assert BUILTIN_RECEPTACLES[target].category == BUILTIN_RECEPTACLES[other].category
        paint = {n: next(c for c, v in PAINT_COLORS.items() if list(v) == rgba)
                 for n, rgba in t["object_colors"].items()}
        assert paint[target] != paint[other]
        assert raw["language"]["referral_expressions"]["place_receptacle_name"] == \
            f"the {paint[target]} {BUILTIN_RECEPTACLES[target].category}"


@pytest.mark.parametrize("name", list(SHIPPED))
def test_shipped_benchmark_is_the_generator_output(name):
    root = data_path("benchmarks") / name
    meta = json.loads((root / "benchmark_metadata.json").read_text())
    shipped = json.loads((root / "benchmark.json").read_text())
    g = meta["generator"]
    assert g["task"] == SHIPPED[name]
    episodes, regenerated = generate_benchmark(g["task"], g["n_houses"], g["episodes_per_house"], g["seed"], name)
    assert shipped == episodes and meta == regenerated
    assert len(shipped) >= 50 and len({e["house_index"] for e in shipped}) >= 10
    assert all({c["type"] for c in e["cameras"]} == {"exocentric", "robot_mounted"} for e in shipped)
