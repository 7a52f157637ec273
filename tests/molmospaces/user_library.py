"""Our own MolmoSpaces-format user asset + grasp library and user scene (as their tutorial lays them out)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from standin import HALF, object_xml, top_down_grasps

UID = "blue_block"


def write_user_library(root: Path) -> Path:
    """``root/asset_library`` with assets_index.json + grasps_index.json; ``root/scene.xml`` + scene_metadata.json."""
    lib = root / "asset_library"
    (lib / UID / "droid").mkdir(parents=True)
    (lib / UID / f"{UID}.xml").write_text(object_xml(UID, "0.1 0.2 0.9 1"))
    meta = {"assetId": UID, "category": "block", "description": "A blue block.", "description_long": "A blue block.",
            "description_short": {"one_word": "block", "two_words": "blue block", "three_words": "small blue block"},
            "synset": "block.n.01"}
    (lib / UID / f"{UID}.json").write_text(json.dumps(meta))
    computed = dict(meta, mass=0.1, boundingBox={"x": 2 * HALF[0], "y": 2 * HALF[1], "z": 2 * HALF[2]})
    (lib / UID / f"{UID}_computed.json").write_text(json.dumps(computed))
    (lib / "assets_index.json").write_text(json.dumps({UID: {
        "uid": UID, "object_path": f"{UID}/{UID}.xml", "metadata_path": f"{UID}/{UID}_computed.json",
        "metadata_npz_path": None}}, indent=4))
    np.savez(lib / UID / "droid" / "grasps.npz", transforms=top_down_grasps())
    (lib / "grasps_index.json").write_text(json.dumps({"articulated_grasp_paths": {},
                                                       "grasp_paths": {"droid": {UID: f"{UID}/droid/grasps.npz"}}}))
    (root / "scene.xml").write_text(f"""<mujoco model="user_scene">
  <option integrator="implicitfast" cone="elliptic" impratio="10" timestep="0.005"/>
  <asset>
    <model name="block_model" file="asset_library/{UID}/{UID}.xml"/>
  </asset>
  <worldbody>
    <light name="key" pos="0 0 3" dir="0 0 -1" directional="true"/>
    <geom name="floor" type="plane" size="3 3 0.1" rgba="0.4 0.4 0.45 1"/>
    <body name="table" pos="0.3 0 0">
      <geom name="table_top" type="box" size="0.5 0.6 0.02" pos="0 0 0.73" rgba="0.6 0.5 0.4 1"/>
    </body>
    <frame pos="0.5 0.05 {0.75 + HALF[2]}">
      <attach model="block_model" prefix=""/>
    </frame>
  </worldbody>
</mujoco>
""")
    (root / "scene_metadata.json").write_text(json.dumps({"objects": {UID: {
        "asset_id": UID, "object_id": UID, "category": "block", "is_static": False}}}))
    return lib


def user_pick_episode(house_index: int = 0) -> dict:
    pose = [0.5, 0.05, 0.75 + HALF[2], 1.0, 0.0, 0.0, 0.0]
    return {
        "house_index": house_index, "scene_dataset": "user", "data_split": "val", "seed": None,
        "robot": {"robot_name": "franka", "init_qpos": {"arm": [0.0, -0.55, 0.0, -2.4, 0.0, 1.85, 0.785],
                                                        "gripper": [0.0]}},
        "img_resolution": [96, 64],
        "cameras": [{"name": "exo", "type": "exocentric", "pos": [-0.4, 0.0, 1.6], "up": [0, 0, 1],
                     "forward": [0.8, 0.0, -0.6], "fov": 60.0}],
        "scene_modifications": {"added_objects": {}, "object_poses": {UID: pose}},
        "task": {"task_cls": "molmo_spaces.tasks.pick_task.PickTask",
                 "robot_base_pose": [0.0, 0.0, 0.75, 1.0, 0.0, 0.0, 0.0], "pickup_obj_name": UID,
                 "pickup_obj_start_pose": pose, "succ_pos_threshold": 0.01},
        "language": {"task_description": "Pick up the blue block"},
    }
