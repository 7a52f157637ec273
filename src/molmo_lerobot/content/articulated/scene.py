"""The articulated tabletop scene dataset (``articulated_tabletop``), a scene plugin that also
provides the library of its articulated objects (``articulated``).

House ``i`` is drawn from a random stream seeded by ``i`` alone: table height and colours,
one main articulated object (microwave, sliding cabinet, hinged cabinet or drawer chest from
:mod:`molmo_lerobot.content.articulated.objects`) in front of the robot with its handles 0.62–0.68 m
ahead, in half the houses a drawer chest beside it, and two built-in objects as
distractors at the table's front corners, out of the doors' swing. The robot stands on a
pedestal in front of the table, its base :data:`ROBOT_DROP` below the table top (the Franka
reaches handles with a level hand comfortably about 0.8 m above its base), at the origin
facing +x; objects face it (their local ``-y`` front turned to world ``-x``).

Body names: each articulated object is the body named by its UID; its parts and joints are
prefixed ``"<uid>/"`` (joint ``kitchen_microwave/microwave``).
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS
from molmo_lerobot.assets.catalog import AssetLibraryType
from molmo_lerobot.content.articulated.objects import (
    ARTICULATED_LIBRARY_TYPE,
    ARTICULATED_OBJECTS,
    ArticulatedObject,
)
from molmo_lerobot.sim.scenes import SceneDataset, attach_mjcf, room_spec

_SALT = 0xA471C
N_HOUSES = 1000
#: yaw turning an object's local -y front towards the robot (world -x)
FACING_QUAT = (math.cos(-math.pi / 4), 0.0, 0.0, math.sin(-math.pi / 4))
_MAIN = ("kitchen_microwave", "kitchen_slide_cabinet", "kitchen_hinge_cabinet", "chest")
_CHESTS = sorted(u for u in ARTICULATED_OBJECTS if u.startswith("drawer_chest_"))
_FLOORS = [(0.55, 0.5, 0.45), (0.35, 0.35, 0.38), (0.6, 0.58, 0.55), (0.42, 0.33, 0.26)]
_TABLES = [(0.72, 0.6, 0.45), (0.85, 0.85, 0.82), (0.4, 0.28, 0.18), (0.55, 0.55, 0.58)]
_DISTRACTORS = sorted(u for u, o in BUILTIN_OBJECTS.items() if o.shape in ("box", "cylinder"))
TABLE_X = (0.3, 1.4)
#: how far the robot base sits below the table top
ROBOT_DROP = 0.62
TABLE_HALF_Y = 0.85


def _layout(house_index: int) -> dict[str, Any]:
    """Every random choice of a house, drawn in a fixed order."""
    rng = np.random.default_rng([_SALT, house_index])
    height = float(rng.uniform(0.70, 0.80))
    floor = _FLOORS[rng.integers(len(_FLOORS))]
    table = _TABLES[rng.integers(len(_TABLES))]
    light_az = float(rng.uniform(-math.pi / 3, math.pi / 3))
    kind = _MAIN[rng.integers(len(_MAIN))]
    chests = list(rng.permutation(_CHESTS))
    main = ARTICULATED_OBJECTS[chests.pop() if kind == "chest" else kind]
    front = float(rng.uniform(0.62, 0.68))
    y0 = float(rng.uniform(-0.06, 0.06))
    placed: list[tuple[ArticulatedObject, float, float]] = [(main, front + main.front, y0)]
    if main.category != "drawer_chest" and rng.random() < 0.5:
        chest = ARTICULATED_OBJECTS[chests.pop()]
        side = 1.0 if rng.random() < 0.5 else -1.0
        y = y0 + side * (main.size[0] / 2 + 0.04 + chest.size[0] / 2)
        placed.append((chest, front + chest.front, y))
    distractors = []
    for uid, side in zip(rng.choice(_DISTRACTORS, 2, replace=False), (1.0, -1.0), strict=True):
        obj = BUILTIN_OBJECTS[str(uid)]
        x = float(rng.uniform(0.36, 0.44))
        y = side * float(rng.uniform(0.52, 0.66))
        distractors.append((obj, [x, y, height + obj.half_extents[2], 1.0, 0.0, 0.0, 0.0]))
    return {"height": height, "floor": floor, "table": table, "light_az": light_az, "articulated": placed,
            "distractors": distractors}


def _attach_spec(world: mujoco.MjSpec, child: mujoco.MjSpec, root: str, name: str, pos, quat) -> None:
    frame = world.worldbody.add_frame(pos=list(pos), quat=list(quat))
    frame.attach_body(child.body(root), f"{name}/", "")
    world.body(f"{name}/{root}").name = name


class ArticulatedTabletop(SceneDataset):
    """A table, one or two articulated objects facing the robot, two distractors."""

    name = "articulated_tabletop"
    aliases = ("articulated",)

    def n_houses(self) -> int:
        return N_HOUSES

    def metadata(self, house_index: int) -> dict[str, Any]:
        self.check_house(house_index)
        lay = _layout(house_index)
        h = lay["height"]
        objects: dict[str, Any] = {}
        for obj, x, y in lay["articulated"]:
            objects[obj.uid] = {
                "asset_id": obj.uid, "category": obj.category, "description": obj.description,
                "articulated": True, "default_pose": [x, y, h + obj.root_z, *FACING_QUAT],
                "joints": {j.name: {"joint": f"{obj.uid}/{j.name}", "body": f"{obj.uid}/{j.body}", "type": j.kind,
                                    "closed": 0.0, "open": j.open_q, "label": j.label} for j in obj.joints},
            }
        for obj, pose in lay["distractors"]:
            objects[obj.uid] = {"asset_id": obj.uid, "category": obj.category, "description": obj.description,
                                "articulated": False, "default_pose": pose}
        return {
            "scene_dataset": self.name,
            "house_index": house_index,
            "table_height": h,
            "robot_base_pose": [0.0, 0.0, h - ROBOT_DROP, 1.0, 0.0, 0.0, 0.0],
            "objects": objects,
        }

    def build(self, house_index: int) -> mujoco.MjSpec:
        self.check_house(house_index)
        lay = _layout(house_index)
        world = room_spec(f"{self.name}_{house_index}", lay["floor"])
        wb = world.worldbody
        h, top = lay["height"], 0.02
        hx, cx = (TABLE_X[1] - TABLE_X[0]) / 2, (TABLE_X[1] + TABLE_X[0]) / 2
        table = wb.add_body(name="table", pos=[cx, 0.0, 0.0])
        table.add_geom(name="table_top", type=mujoco.mjtGeom.mjGEOM_BOX, size=[hx, TABLE_HALF_Y, top],
                       pos=[0.0, 0.0, h - top], rgba=[*lay["table"], 1.0], friction=[1.0, 0.01, 0.001])
        for sx in (-1, 1):
            for sy in (-1, 1):
                table.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.03, 0.03, (h - 2 * top) / 2],
                               pos=[sx * (hx - 0.05), sy * (TABLE_HALF_Y - 0.05), (h - 2 * top) / 2],
                               rgba=[*lay["table"], 1.0])
        wb.add_geom(name="pedestal", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.12, 0.12, (h - ROBOT_DROP) / 2],
                    pos=[-0.02, 0.0, (h - ROBOT_DROP) / 2], rgba=[0.3, 0.3, 0.32, 1.0])
        az = lay["light_az"]
        wb.add_light(name="key", pos=[cx - 1.2 * math.cos(az), 1.2 * math.sin(az), h + 1.8],
                     dir=[math.cos(az), -math.sin(az), -1.5], diffuse=[0.7, 0.7, 0.7], castshadow=False)
        wb.add_light(name="fill", pos=[cx, 0.0, h + 2.5], dir=[0.0, 0.0, -1.0], diffuse=[0.3, 0.3, 0.3],
                     castshadow=False)
        for obj, x, y in lay["articulated"]:
            _attach_spec(world, obj.spec(), obj.root_body, obj.uid, (x, y, h + obj.root_z), FACING_QUAT)
        for obj, pose in lay["distractors"]:
            attach_mjcf(world, obj.mjcf(), obj.uid, pos=pose[:3], quat=pose[3:], source=f"house {house_index}")
        return world


@hookimpl
def molmo_scene_datasets() -> list[SceneDataset]:
    return [ArticulatedTabletop()]


@hookimpl
def molmo_asset_libraries() -> list[AssetLibraryType]:
    return [ARTICULATED_LIBRARY_TYPE]
