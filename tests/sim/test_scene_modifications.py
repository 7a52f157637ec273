"""Episode scene modifications: added MJCF objects, primitive objects, removed objects, poses."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing


def test_add_remove_and_place(pick_episodes, run, tmp_path):
    raw = copy.deepcopy(pick_episodes[0])
    mods = raw["scene_modifications"]
    target = raw["task"]["pickup_obj_name"]
    removed = next(n for n in mods["object_poses"] if n != target)
    del mods["object_poses"][removed]
    mods["removed_objects"] = [removed]
    xml = tmp_path / "mug.xml"
    xml.write_text(BUILTIN_OBJECTS["builtin_blue_mug"].mjcf())
    mods["added_objects"] = {"extra_mug": str(xml)}
    mods["primitive_objects"] = {"crate": {"body_name": "crate", "geoms": [
        {"name_suffix": "_box", "geom_type": "box", "size": [0.03, 0.03, 0.03], "rgba": [0.5, 0.3, 0.1, 1]}]}}
    mods["object_poses"]["extra_mug"] = [0.5, 0.3, 1.2, 1, 0, 0, 0]
    mods["object_poses"]["crate"] = [0.3, -0.3, 1.3, 1, 0, 0, 0]
    env = build_env(parse_episode(raw, run.plugins), Timing(), run)
    try:
        env.reset(0)
        with pytest.raises(ValueError, match=f"no body '{removed}'"):
            env.body_id(removed)
        assert np.allclose(env.body_pose("extra_mug")[:3], [0.5, 0.3, 1.2])
        assert np.allclose(env.body_pose("crate")[:3], [0.3, -0.3, 1.3])
    finally:
        env.close()


def test_bad_modifications_are_named(pick_episodes, run, tmp_path):
    raw = copy.deepcopy(pick_episodes[0])
    raw["scene_modifications"]["removed_objects"] = ["nothing_here"]
    with pytest.raises(ValueError, match=r"removed_objects: no body 'nothing_here'"):
        build_env(parse_episode(raw, run.plugins), Timing(), run)
    raw = copy.deepcopy(pick_episodes[0])
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><body name='x'>")
    raw["scene_modifications"]["added_objects"] = {"junk": str(bad)}
    with pytest.raises(ValueError, match=r"added_objects\['junk'\]: cannot parse MJCF"):
        build_env(parse_episode(raw, run.plugins), Timing(), run)
