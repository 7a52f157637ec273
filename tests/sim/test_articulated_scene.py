"""Articulated objects (asset + per-joint grasp library), the articulated tabletop scene, open/close generation."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from molmo_lerobot.assets.grasps import GraspError
from molmo_lerobot.content.articulated.generate import generate_benchmark
from molmo_lerobot.content.articulated.objects import ARTICULATED_OBJECTS, ArticulatedAssetLibrary, handle_grasps
from molmo_lerobot.content.articulated.scene import ArticulatedTabletop
from molmo_lerobot.context import RunContext


def test_articulated_library_is_in_the_default_catalog_with_per_joint_grasps():
    cat = RunContext.build().catalog
    doc = cat.annotation("kitchen_microwave")
    assert doc["category"] == "microwave" and doc["joints"]["microwave"]["open"] == pytest.approx(-2.094)
    assert cat.locate_uid("drawer_chest_white").library == "articulated"
    assert cat.grasp_joints("kitchen_hinge_cabinet") == ["left_hinge_cabinet", "right_hinge_cabinet"]
    g = cat.get_grasps("kitchen_hinge_cabinet", robot="franka", joint="right_hinge_cabinet")
    assert g.ndim == 3 and g.shape[1:] == (4, 4)
    assert cat.count_grasps("kitchen_hinge_cabinet", joint="right_hinge_cabinet") == len(g)
    with pytest.raises(GraspError, match="joint 'nope'"):
        cat.get_grasps("kitchen_microwave", joint="nope")


@pytest.mark.parametrize("uid", sorted(ARTICULATED_OBJECTS))
def test_objects_compile_with_their_joints_and_grasps_sit_on_the_handle(uid):
    obj = ARTICULATED_OBJECTS[uid]
    model = obj.spec().compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for j in obj.joints:
        jnt = model.joint(j.name)
        assert model.body(int(jnt.bodyid[0])).name == j.body
        assert sorted(jnt.range) == pytest.approx(sorted([0.0, j.open_q]))
        grasps = handle_grasps(obj, j.name)
        for T in grasps:  # rotation, approach into the front (+y), fingers across the bar
            assert T[:3, :3].T @ T[:3, :3] == pytest.approx(np.eye(3), abs=1e-9)
            assert T[:3, 2] == pytest.approx([0.0, 1.0, 0.0])
            assert np.linalg.norm(T[:3, 3] - np.asarray(j.handle_pos)) <= j.handle_half_length
        # a geom of the moving body lies at the handle centre (the bar the grasps close on)
        body = model.body(j.body).id
        centres = [data.geom_xpos[g] for g in range(model.ngeom) if model.geom_bodyid[g] == body]
        handle_world = data.xpos[body] + data.xmat[body].reshape(3, 3) @ np.asarray(j.handle_pos)
        assert min(np.linalg.norm(c - handle_world) for c in centres) < 1e-6


def test_library_metadata_and_mjcf():
    lib = ArticulatedAssetLibrary()
    assert sorted(lib.uids()) == sorted(ARTICULATED_OBJECTS)
    assert "<mujoco" in lib.mjcf("drawer_chest_wood")
    with pytest.raises(LookupError, match="no UID 'nope'"):
        lib.metadata("nope")


def test_scene_is_deterministic_and_compiles():
    scene = ArticulatedTabletop()
    for house in (0, 3):
        meta = scene.metadata(house)
        assert meta == scene.metadata(house)
        model = scene.build(house).compile()
        articulated = [o for o in meta["objects"].values() if o["articulated"]]
        assert 1 <= len(articulated) <= 2 and len(meta["objects"]) - len(articulated) == 2
        for obj in articulated:
            for j in obj["joints"].values():
                assert model.joint(j["joint"]).id >= 0 and model.body(j["body"]).id >= 0
    with pytest.raises(ValueError, match="house_index 1000 out of range"):
        scene.build(1000)


def test_generation_is_deterministic_and_starts_in_the_right_state():
    a = generate_benchmark("close", 3, 2, 7, "t")
    assert json.dumps(a) == json.dumps(generate_benchmark("close", 3, 2, 7, "t"))
    episodes, meta = a
    assert meta["num_episodes"] == 6 and len(meta["house_counts"]) == 3
    for e in episodes:
        t = e["task"]
        obj = ARTICULATED_OBJECTS[t["pickup_obj_name"]]
        j = obj.joint(t["joint_name"].split("/", 1)[1])
        assert j.kind == "slide" and 0.95 <= t["joint_start_position"] / j.open_q <= 1.0
        assert e["language"]["task_description"].startswith("close the ")
        assert [c["name"] for c in e["cameras"]] == ["exterior", "wrist"]
    opened = generate_benchmark("open", 2, 1, 0, "t")[0]
    assert all(e["task"]["joint_start_position"] == 0.0 and e["task"]["task_type"] == "open" for e in opened)
    with pytest.raises(ValueError, match="unknown task 'pick'"):
        generate_benchmark("pick", 1, 1, 0, "t")
