"""Grasps of the libero objects: computed from their collision geometry, deterministic, cached; the top
grasp lifts the object with franka_droid's Robotiq and with franka's Panda hand (a floating gripper,
``grasp_lift.py``).

The default run lifts two objects with the Robotiq; ``-m slow`` checks determinism and caching and lifts every
graspable object with each gripper."""

from __future__ import annotations

import numpy as np
import pytest
from grasp_lift import LIFT, lift_height

from molmo_lerobot.content.libero.grasps import GRIPPERS, LiberoGraspLibrary, compute_grasps
from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS

GRASPABLE = sorted(u for u, o in LIBERO_OBJECTS.items() if o.graspable)
QUICK = ["libero_black_book", "libero_milk"]


@pytest.fixture
def library(tmp_path, monkeypatch):
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path))
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "16")
    return LiberoGraspLibrary()


def _lifts(library: LiberoGraspLibrary, uid: str, robot: str = "franka_droid") -> None:
    obj = LIBERO_OBJECTS[uid]
    grasps = library.load(uid, robot)
    assert grasps is not None and grasps.shape[1:] == (4, 4) and len(grasps) >= 8
    rise = lift_height(obj.mjcf(), uid, obj.half_extents[2] + 0.001, grasps[0], robot)
    assert rise > 0.8 * LIFT, f"{uid}: {robot}'s top grasp lifted it {rise:.3f} m of {LIFT} m"


@pytest.mark.slow
def test_grasps_are_deterministic_cached_and_only_for_known_grippers(library):
    first = library.load("libero_black_book", "franka_droid")
    assert library.path("libero_black_book", "franka_droid").is_relative_to(library.root)
    np.testing.assert_array_equal(first, compute_grasps("libero_black_book", "franka_droid"))
    assert library.load("libero_black_book", "stretch") is None  # no gripper model: the catalog looks elsewhere
    for T in first:  # proper poses: orthonormal, +z approach from above or the side, never from below
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
        assert T[2, 2] <= 1e-9


@pytest.mark.parametrize("uid", QUICK)
def test_top_grasp_lifts(library, uid):
    _lifts(library, uid)


@pytest.mark.slow
@pytest.mark.parametrize("robot", sorted(GRIPPERS))
@pytest.mark.parametrize("uid", GRASPABLE)
def test_top_grasp_lifts_every_object(library, uid, robot):
    if robot == "franka_droid" and uid in QUICK:
        pytest.skip("lifted in the default run")
    _lifts(library, uid, robot)
