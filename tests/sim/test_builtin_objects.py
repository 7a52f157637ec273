"""The built-in object set: valid MJCF, metadata, and grasps a Franka hand can execute."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from molmo_lerobot.assets.builtin import (
    BUILTIN_OBJECTS,
    FINGERTIP_CLEARANCE,
    HANDS,
    BuiltinObject,
    analytic_grasps,
)


def test_at_least_ten_graspable_objects():
    assert len(BUILTIN_OBJECTS) >= 10
    assert all(uid == obj.uid for uid, obj in BUILTIN_OBJECTS.items())


@pytest.mark.parametrize("obj", list(BUILTIN_OBJECTS.values()), ids=list(BUILTIN_OBJECTS))
def test_object_mjcf_and_metadata(obj):
    model = mujoco.MjSpec.from_string(obj.mjcf()).compile()
    assert model.nbody == 2 and model.body(1).name == obj.uid and model.njnt == 1
    assert model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert model.body_mass[1] == pytest.approx(obj.mass)
    meta = obj.metadata()
    assert meta["assetId"] == obj.uid and meta["synset"] == obj.synset
    assert set(meta["description_short"]) == {"one_word", "two_words", "three_words"}
    # bounding box = the compiled geom's extents
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert max(meta["boundingBox"].values()) <= 2 * model.geom_rbound[0] + 1e-9


@pytest.mark.parametrize("robot", sorted(HANDS))
@pytest.mark.parametrize("obj", list(BUILTIN_OBJECTS.values()), ids=list(BUILTIN_OBJECTS))
def test_grasps_are_valid_poses_that_fit_the_hand(obj, robot):
    hand = HANDS[robot]
    grasps = analytic_grasps(obj, hand)
    assert grasps.ndim == 3 and grasps.shape[1:] == (4, 4) and grasps.dtype == np.float64 and len(grasps) >= 4
    R = grasps[:, :3, :3]
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(grasps[:, 3], [0, 0, 0, 1])
    half = np.asarray(obj.half_extents)
    for g in grasps:
        # the finger axis spans at most the hand's opening; the fingertips stay inside the far side
        span = 2 * np.abs(g[:3, 1]) @ half if obj.shape == "box" else 2 * obj.size[0]
        assert span <= hand.max_grasp_width + 1e-9
        tip = g[:3, 3] + hand.tcp_to_fingertip * g[:3, 2]
        assert np.all(np.abs(tip) <= half + 1e-9)
        # the TCP (gripping centre) sits as deep as the fingertips allow: at the centre, or with
        # the fingertips at the clearance from the far side, or the palm at it from the near side
        depth = float(g[:3, 3] @ g[:3, 2])
        far = float(np.abs(g[:3, 2]) @ half) if obj.shape == "box" else None
        if depth < -1e-9 and far is not None:
            palm_gap = far + depth - hand.palm_to_tcp  # near side to the palm, negative: inside
            tip_gap = far - depth - hand.tcp_to_fingertip
            assert min(abs(tip_gap - FINGERTIP_CLEARANCE), abs(-palm_gap - FINGERTIP_CLEARANCE)) < 1e-9
    # top-down grasps (approach -z in the object frame) exist at several yaws
    top = grasps[grasps[:, 2, 2] < -0.99]
    assert len({round(float(np.arctan2(g[1, 1], g[0, 1])), 3) for g in top}) >= 2


def test_bad_objects_are_rejected():
    with pytest.raises(ValueError, match="shape 'cone'"):
        BuiltinObject("x", "c", "cone", (0.1,), (1, 0, 0, 1), 0.1, "red cone", "cone.n.01")
    with pytest.raises(ValueError, match="box needs 3 positive sizes"):
        BuiltinObject("x", "c", "box", (0.1, 0.1), (1, 0, 0, 1), 0.1, "red box", "box.n.01")
    wide = BuiltinObject("wide", "c", "sphere", (0.2,), (1, 0, 0, 1), 0.1, "red ball", "ball.n.01")
    with pytest.raises(ValueError, match="no grasp fits"):
        analytic_grasps(wide)
