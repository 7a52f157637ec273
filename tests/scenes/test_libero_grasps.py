"""Grasps of the libero objects: computed from their collision geometry, deterministic, cached; the top
grasp lifts the object with franka_droid's Robotiq (a floating gripper, ``grasp_lift.py``).

The default run lifts two objects; ``-m slow`` checks determinism and caching and lifts every graspable object."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from grasp_lift import LIFT, lift_height

from molmo_lerobot.libero.grasps import LiberoGraspLibrary, compute_grasps
from molmo_lerobot.libero.objects import LIBERO_OBJECTS

GRASPABLE = sorted(u for u, o in LIBERO_OBJECTS.items() if o.graspable)
QUICK = ["libero_black_book", "libero_milk"]


@pytest.fixture
def library(tmp_path, monkeypatch):
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path))
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "16")
    return LiberoGraspLibrary()


def _lifts(library: LiberoGraspLibrary, uid: str) -> None:
    obj = LIBERO_OBJECTS[uid]
    grasps = library.load(uid, "franka_droid")
    assert grasps is not None and grasps.shape[1:] == (4, 4) and len(grasps) >= 8
    rise = lift_height(obj.mjcf(), uid, obj.half_extents[2] + 0.001, grasps[0])
    assert rise > 0.8 * LIFT, f"{uid}: the top grasp lifted it {rise:.3f} m of {LIFT} m"


@pytest.mark.slow
def test_grasps_are_deterministic_cached_and_only_for_known_grippers(library):
    first = library.load("libero_black_book", "franka_droid")
    assert library.path("libero_black_book", "franka_droid").is_relative_to(library.root)
    np.testing.assert_array_equal(first, compute_grasps("libero_black_book", "franka_droid"))
    assert library.load("libero_black_book", "franka") is None  # no Panda hand model: the catalog looks elsewhere
    for T in first:  # proper poses: orthonormal, +z approach from above or the side, never from below
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
        assert T[2, 2] <= 1e-9


@pytest.mark.parametrize("uid", QUICK)
def test_top_grasp_lifts(library, uid):
    _lifts(library, uid)


@pytest.mark.slow
@pytest.mark.parametrize("uid", [u for u in GRASPABLE if u not in QUICK])
def test_top_grasp_lifts_every_object(library, uid):
    _lifts(library, uid)
