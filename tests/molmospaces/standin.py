"""A small stand-in of MolmoSpaces' assets dir, in its exact layout, from geometry made here.

::

    objects/thor/Kitchen/<uid>.xml                     thor objects (box "mugs")
    objects/objaverse/<uid>/<uid>.xml                  one objaverse object
    objects/objathor_metadata/objects_metadata.json.gz annotations of all of them
    .lmdb/objathor_metadata/<version>/                 MolmoSpaces' LMDB of the same (zstd pickles)
    grasps/droid/<uid>/<uid>_grasps_filtered.npz       top-down grasps, MolmoSpaces' TCP convention
    grasps/droid_objaverse/<uid>/<uid>_grasps_filtered.npz
    scenes/ithor/FloorPlan<i>_physics.xml              + FloorPlan<i>_physics_metadata.json
    scenes/procthor-10k-val/val_<i>_ceiling.xml        (+ val_<i>.xml) + val_<i>_metadata.json
    scenes/procthor-objaverse-val/…, scenes/holodeck-objaverse-val/…

Every house is a room with a table; the robot stands on the table's near edge (its base pose
is returned with the house) and the target object rests in front of it.
"""

from __future__ import annotations

import gzip
import json
import math
import pickle
from dataclasses import dataclass
from pathlib import Path

import lmdb
import numpy as np
import zstandard

from molmo_lerobot.robots.franka_droid import BASE_SIZE

HALF = (0.02, 0.02, 0.03)  # the box objects' half sizes
TABLE_H = 0.75
THOR_UIDS = ("Mug_1", "Mug_2")
OBJAVERSE_UID = "0f3c2e9a8b7d4c6e9a1b2c3d4e5f6a7b"
LMDB_VERSION = "20260129"
COMPLETE = "__LMDBMap__dump_complete__"


def object_xml(name: str, rgba: str, free: bool = True) -> str:
    joint = "<freejoint/>" if free else ""
    return (f'<mujoco model="{name}"><worldbody><body name="{name}">{joint}'
            f'<geom name="{name}_geom" type="box" size="{HALF[0]} {HALF[1]} {HALF[2]}" rgba="{rgba}" mass="0.1" '
            f'friction="1.5 0.01 0.001"/></body></worldbody></mujoco>\n')


def top_down_grasps() -> np.ndarray:
    """TCP poses in the object frame: +z approach pointing down, fingers along x or y (MolmoSpaces' convention)."""
    out = []
    for yaw in (0.0, math.pi / 2, math.pi, -math.pi / 2):
        T = np.eye(4)
        c, s = math.cos(yaw), math.sin(yaw)
        y = np.array([c, s, 0.0])
        z = np.array([0.0, 0.0, -1.0])
        T[:3, 0], T[:3, 1], T[:3, 2] = np.cross(y, z), y, z
        T[:3, 3] = [0.0, 0.0, HALF[2] - 0.02]  # fingertips 5 mm above the bottom
        out.append(T)
    return np.stack(out)


def annotation(uid: str, category: str) -> dict:
    return {"assetId": uid, "category": category, "description": f"a {category}", "description_long": f"A {category}.",
            "description_short": {"one_word": category, "two_words": f"small {category}",
                                  "three_words": f"small plain {category}"},
            "synset": f"{category}.n.01", "mass": 0.1, "boundingBox": {"x": 0.04, "y": 0.04, "z": 0.06}}


@dataclass(frozen=True)
class House:
    dataset: str
    split: str
    index: int
    xml: Path
    body: str  # the object to pick
    uid: str
    base_pose: list[float]
    object_pose: list[float]


def _yaw_quat(yaw: float) -> list[float]:
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


def _rot(yaw: float, x: float, y: float) -> tuple[float, float]:
    return x * math.cos(yaw) - y * math.sin(yaw), x * math.sin(yaw) + y * math.cos(yaw)


def write_scene(path: Path, origin: tuple[float, float], yaw: float, objects: list[tuple[str, str, str]],
                option: str) -> tuple[list[float], list[list[float]]]:
    """A room with a table; ``objects`` are (body, uid, how) with how = 'inline' or an MJCF path to attach.

    Returns the robot base pose and each object's resting pose (world frame).
    """
    ox, oy = origin
    cx, cy = _rot(yaw, 0.3, 0.0)
    q = " ".join(f"{v:.9f}" for v in _yaw_quat(yaw))
    models, bodies, poses = [], [], []
    for k, (body, _uid, how) in enumerate(objects):
        lx, ly = _rot(yaw, 0.5, -0.12 + 0.24 * k)
        pose = [ox + lx, oy + ly, TABLE_H + HALF[2], *_yaw_quat(yaw)]
        poses.append(pose)
        at = f'pos="{pose[0]:.9f} {pose[1]:.9f} {pose[2]:.9f}" quat="{q}"'
        if how == "inline":
            inner = object_xml(body, "0.8 0.2 0.2 1").split("<worldbody>")[1].split("</worldbody>")[0]
            bodies.append(f"<frame {at}>{inner}</frame>")
        else:
            models.append(f'<model name="m{k}" file="{how}"/>')
            bodies.append(f'<frame {at}><attach model="m{k}" prefix="{body}/"/></frame>')
    xml = f"""<mujoco model="{path.stem}">
  <option {option}/>
  <asset>{''.join(models)}</asset>
  <worldbody>
    <light name="sun" pos="{ox} {oy} 3" dir="0 0 -1" directional="true" diffuse="0.8 0.8 0.8"/>
    <geom name="floor" type="plane" size="20 20 0.1" rgba="0.5 0.5 0.5 1"/>
    <body name="table_1_0_0" pos="{ox + cx:.9f} {oy + cy:.9f} 0" quat="{q}">
      <geom name="table_top" type="box" size="0.5 0.6 0.02" pos="0 0 {TABLE_H - 0.02}" rgba="0.6 0.45 0.3 1"
            friction="1 0.01 0.001"/>
      <geom type="box" size="0.03 0.03 {(TABLE_H - 0.04) / 2}" pos="0.4 0.5 {(TABLE_H - 0.04) / 2}"/>
      <geom type="box" size="0.03 0.03 {(TABLE_H - 0.04) / 2}" pos="0.4 -0.5 {(TABLE_H - 0.04) / 2}"/>
    </body>
    {''.join(bodies)}
  </worldbody>
</mujoco>
"""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(xml)
    return [ox, oy, TABLE_H, *_yaw_quat(yaw)], poses


def write_metadata(path: Path, objects: dict[str, str]) -> None:
    meta = {"objects": {body: {"asset_id": uid, "object_id": body, "category": uid.split("_")[0].lower(),
                               "is_static": False} for body, uid in objects.items()}}
    meta["objects"]["table_1_0_0"] = {"asset_id": "Table_1", "object_id": "table_1_0_0", "category": "table",
                                      "is_static": True}
    path.write_text(json.dumps(meta, indent=1))


def save_npz(path: Path, transforms: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, transforms=transforms)


def build_assets(root: Path) -> list[House]:
    """Write the stand-in tree under ``root``; returns the houses with their pick targets."""
    thor = root / "objects" / "thor" / "Kitchen"
    thor.mkdir(parents=True)
    docs = {}
    for uid in THOR_UIDS:
        (thor / f"{uid}.xml").write_text(object_xml(uid, "0.2 0.4 0.8 1"))
        docs[uid] = annotation(uid, "mug")
        save_npz(root / "grasps" / "droid" / uid / f"{uid}_grasps_filtered.npz", top_down_grasps())
    (thor / "Bowl_27.xml").write_text(object_xml("Bowl_27", "0.9 0.9 0.9 1"))
    docs["Bowl_27"] = annotation("Bowl_27", "bowl")
    obja = root / "objects" / "objaverse" / OBJAVERSE_UID
    obja.mkdir(parents=True)
    (obja / f"{OBJAVERSE_UID}.xml").write_text(object_xml(OBJAVERSE_UID, "0.2 0.8 0.3 1"))
    docs[OBJAVERSE_UID] = annotation(OBJAVERSE_UID, "cup")
    save_npz(root / "grasps" / "droid_objaverse" / OBJAVERSE_UID / f"{OBJAVERSE_UID}_grasps_filtered.npz",
             top_down_grasps())
    meta_dir = root / "objects" / "objathor_metadata"
    meta_dir.mkdir(parents=True)
    with gzip.open(meta_dir / "objects_metadata.json.gz", "wt") as fh:
        json.dump(docs, fh)
    write_their_lmdb(root / ".lmdb" / "objathor_metadata" / LMDB_VERSION, docs)

    houses = []
    # iTHOR: FloorPlan15 is a val house (15 % 100 in 13..24); FloorPlan1 a train house
    for index, split, origin, yaw in ((15, "val", (1.0, -2.0), 0.0), (1, "train", (0.0, 0.0), 0.0)):
        xml = root / "scenes" / "ithor" / f"FloorPlan{index}_physics.xml"
        body = f"Mug_1_{index}_0_0"
        base, poses = write_scene(xml, origin, yaw, [(body, "Mug_1", "inline")],
                                  'integrator="implicitfast" cone="elliptic" impratio="10"')
        write_metadata(xml.with_name(f"FloorPlan{index}_physics_metadata.json"), {body: "Mug_1"})
        houses.append(House("ithor", split, index, xml, body, "Mug_1", base, poses[0]))
    # ProcTHOR / Holodeck layout: <split>_<i>_ceiling.xml (+ base variant), objects attached from objects/
    for dataset, index, origin, yaw in (("procthor-10k", 3, (4.0, 2.5), math.pi / 2),
                                        ("procthor-10k", 7, (-1.5, -2.0), 0.3),
                                        ("procthor-objaverse", 2, (-3.0, 1.0), math.pi),
                                        ("procthor-objaverse", 4, (1.0, 6.0), -0.4),
                                        ("holodeck-objaverse", 5, (2.0, -4.0), -math.pi / 2),
                                        ("holodeck-objaverse", 9, (5.5, 0.5), 2.0)):
        d = root / "scenes" / f"{dataset}-val"
        rel_thor = "../../objects/thor/Kitchen/Mug_2.xml"
        rel_obja = f"../../objects/objaverse/{OBJAVERSE_UID}/{OBJAVERSE_UID}.xml"
        mug, cup = "mug_2_1_0_0", f"obja_{OBJAVERSE_UID}_1_0_0"
        objects = [(mug, "Mug_2", rel_thor), (cup, OBJAVERSE_UID, rel_obja)]
        option = 'integrator="implicitfast" cone="elliptic" impratio="10"'
        base, poses = write_scene(d / f"val_{index}_ceiling.xml", origin, yaw, objects, option)
        write_scene(d / f"val_{index}.xml", origin, yaw, objects, option)
        write_metadata(d / f"val_{index}_metadata.json", {f"{mug}/Mug_2": "Mug_2",
                                                          f"{cup}/{OBJAVERSE_UID}": OBJAVERSE_UID})
        target, uid, pose = ((f"{cup}/{OBJAVERSE_UID}", OBJAVERSE_UID, poses[1]) if "objaverse" in dataset
                             else (f"{mug}/Mug_2", "Mug_2", poses[0]))
        houses.append(House(dataset, "val", index, d / f"val_{index}_ceiling.xml", target, uid, base, pose))
    return houses


def write_their_lmdb(path: Path, docs: dict) -> None:
    """MolmoSpaces' metadata LMDB: zstd-compressed pickles, completion key last."""
    path.mkdir(parents=True)
    env = lmdb.open(str(path), map_size=1 << 24)
    with env.begin(write=True) as txn:
        for uid, doc in docs.items():
            full = dict(doc, clip_img_features=np.full((3, 4), 0.5, dtype=np.float16))
            txn.put(uid.encode(), zstandard.compress(pickle.dumps(full)))
        txn.put(COMPLETE.encode(), zstandard.compress(pickle.dumps(COMPLETE)))
    env.close()


FRANKA_ARM = [0.0, -0.55, 0.0, -2.4, 0.0, 1.85, 0.785]


def pick_episode(house: House, robot: str = "franka", gripper: list[float] | None = None,
                 cameras: list[dict] | None = None) -> dict:
    """A MolmoSpaces-format pick episode on ``house`` (their field set and defaults). ``franka_droid``
    stands on MolmoSpaces' pedestal: its base pose is lowered by the pedestal's height, as their base
    poses stand on the floor, so the arm's root stays where the Panda's is."""
    base_pose = list(house.base_pose)
    if robot == "franka_droid":
        base_pose[2] = round(base_pose[2] - BASE_SIZE[2], 5)
    bx, by, bz = house.base_pose[:3]
    yaw = 2 * math.atan2(house.base_pose[6], house.base_pose[3])
    fx, fy = _rot(yaw, 1.0, 0.0)
    exo = {"name": "exo_camera_1", "type": "exocentric", "pos": [bx - 0.4 * fx, by - 0.4 * fy, bz + 0.8],
           "up": [0.0, 0.0, 1.0], "forward": [fx * 0.8, fy * 0.8, -0.6], "fov": 60.0, "record_depth": False}
    goal = list(house.object_pose)
    goal[2] += 0.05
    return {
        "source": {"h5_file": f"/standin/{house.dataset}/house_{house.index}/trajectories.h5", "traj_key": "traj_0",
                   "episode_length": 60, "camera_system_class": "FrankaDroidCameraSystem",
                   "source_data_date": "2026-01-13", "benchmark_created_date": "2026-01-22"},
        "house_index": house.index, "scene_dataset": house.dataset, "data_split": house.split, "seed": None,
        "robot": {"robot_name": robot, "init_qpos": {"base": [], "arm": FRANKA_ARM, "gripper": gripper or [0.0]}},
        "img_resolution": [96, 64],
        "cameras": [exo] if cameras is None else cameras,
        "scene_modifications": {"added_objects": {}, "object_poses": {house.body: house.object_pose}},
        "task": {"task_cls": "molmo_spaces.tasks.pick_task.PickTask", "robot_base_pose": base_pose,
                 "pickup_obj_name": house.body, "pickup_obj_start_pose": house.object_pose,
                 "pickup_obj_goal_pose": goal, "succ_pos_threshold": 0.01},
        "language": {"task_description": "Pick up the mug", "referral_expressions": {"pickup_obj_name": "mug"},
                     "referral_expressions_priority": {}},
    }


def main(argv: list[str] | None = None) -> None:
    """``python tests/molmospaces/standin.py OUT``: the stand-in tree at OUT/assets, a pick benchmark at OUT/bench."""
    import sys

    out = Path((argv or sys.argv[1:])[0])
    houses = build_assets(out / "assets")
    (out / "bench").mkdir(parents=True)
    (out / "bench" / "benchmark.json").write_text(json.dumps([pick_episode(h) for h in houses], indent=1))
    print(f"MLSPACES_ASSETS_DIR={out / 'assets'} molmo-eval policy=scripted benchmark.path={out / 'bench'}")


if __name__ == "__main__":
    main()
