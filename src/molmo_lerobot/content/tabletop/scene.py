"""The procedural tabletop scene dataset (``procedural_tabletop``), a scene plugin that also
provides the library of its built-in objects (``builtin``).

House ``i`` is generated from a random stream seeded by ``i`` alone: floor and table
colours, table size and height, light directions, 4–6 objects from the built-in set
(no two with the same colour and category, so "the red mug" names exactly one) and three
receptacles (two of one category in different colours, one of another category), placed
only in ``procedural_tabletop_receptacles``. The
robot stands at the near edge of the table, on its top surface, facing +x. Objects start
in a default row at the far side, receptacles parked on the table's side strips outside
the robot's workspace; episodes place them with ``object_poses``. Receptacles are drawn
after everything else, so adding them left the rest of every house unchanged.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, BUILTIN_RECEPTACLES, BuiltinObject, BuiltinReceptacle
from molmo_lerobot.assets.catalog import AssetLibraryType
from molmo_lerobot.assets.libraries import BuiltinAssetLibrary
from molmo_lerobot.sim.scenes import SceneDataset, attach_mjcf, room_spec

#: salt that keeps house streams apart from every other use of the house index
_SALT = 0x7AB1E
N_HOUSES = 1000

_FLOORS = [(0.55, 0.5, 0.45), (0.35, 0.35, 0.38), (0.6, 0.58, 0.55), (0.42, 0.33, 0.26), (0.25, 0.3, 0.35)]
_TABLES = [(0.72, 0.6, 0.45), (0.85, 0.85, 0.82), (0.4, 0.28, 0.18), (0.55, 0.55, 0.58), (0.9, 0.88, 0.8)]
_WALLS = [(0.82, 0.82, 0.78), (0.7, 0.75, 0.8), (0.78, 0.72, 0.62), (0.6, 0.65, 0.6)]


def _house_rng(house_index: int) -> np.random.Generator:
    return np.random.default_rng([_SALT, house_index])


def _layout(house_index: int) -> dict[str, Any]:
    """Every random choice of a house, drawn in a fixed order."""
    rng = _house_rng(house_index)
    height = float(rng.uniform(0.70, 0.80))
    half_x = float(rng.uniform(0.45, 0.55))
    half_y = float(rng.uniform(0.55, 0.75))
    floor = _FLOORS[rng.integers(len(_FLOORS))]
    table = _TABLES[rng.integers(len(_TABLES))]
    wall = _WALLS[rng.integers(len(_WALLS))]
    light_az = float(rng.uniform(-math.pi / 3, math.pi / 3))
    n_objects = int(rng.integers(4, 7))
    chosen: list[BuiltinObject] = []
    for k in rng.permutation(len(BUILTIN_OBJECTS)):
        obj = list(BUILTIN_OBJECTS.values())[k]
        if all((o.color, o.category) != (obj.color, obj.category) for o in chosen):
            chosen.append(obj)
        if len(chosen) == n_objects:
            break
    return {"height": height, "half_x": half_x, "half_y": half_y, "floor": floor, "table": table, "wall": wall,
            "light_az": light_az, "objects": chosen, "receptacles": _receptacles(rng)}


def _receptacles(rng: np.random.Generator) -> list[BuiltinReceptacle]:
    """Two receptacles of one category (different colours) and one of another category."""
    by_category: dict[str, list[BuiltinReceptacle]] = {}
    for rec in BUILTIN_RECEPTACLES.values():
        by_category.setdefault(rec.category, []).append(rec)
    categories = sorted(by_category)
    first, second = (categories[k] for k in rng.choice(len(categories), 2, replace=False))
    pair = [by_category[first][k] for k in rng.choice(len(by_category[first]), 2, replace=False)]
    return [*pair, by_category[second][int(rng.integers(len(by_category[second])))]]


class ProceduralTabletop(SceneDataset):
    """A table, a Franka-sized workspace and a handful of built-in objects per house."""

    name = "procedural_tabletop"
    aliases: tuple[str, ...] = ("tabletop",)
    #: whether houses include their three receptacles (a separate, named scene dataset, so
    #: that adding receptacles never changed the scenes of benchmarks made without them)
    WITH_RECEPTACLES = False
    #: table x extent starts this far behind the robot base
    TABLE_BACK = 0.2
    #: where objects may be placed, relative to the robot base (x forward, y left)
    REGION_X = (0.33, 0.62)
    REGION_Y = (-0.26, 0.26)

    def n_houses(self) -> int:
        return N_HOUSES

    def metadata(self, house_index: int) -> dict[str, Any]:
        self.check_house(house_index)
        lay = _layout(house_index)
        return {
            "scene_dataset": self.name,
            "house_index": house_index,
            "table_height": lay["height"],
            "table_extent": {"x": [-self.TABLE_BACK, 2 * lay["half_x"] - self.TABLE_BACK],
                             "y": [-lay["half_y"], lay["half_y"]]},
            "robot_base_pose": [0.0, 0.0, lay["height"], 1.0, 0.0, 0.0, 0.0],
            "placement_region": {"x": list(self.REGION_X), "y": list(self.REGION_Y), "z": lay["height"]},
            "objects": {
                obj.uid: {"asset_id": obj.uid, "category": obj.category, "color": obj.color,
                          "description": obj.description, "default_pose": pose,
                          "receptacle": isinstance(obj, BuiltinReceptacle)}
                for obj, pose in self._placements(lay)
            },
        }

    def _placements(self, lay: dict[str, Any]) -> list[tuple[BuiltinObject | BuiltinReceptacle, list[float]]]:
        """Every object (and receptacle, where the dataset has them) of a house with its default pose."""
        placed: list[tuple[BuiltinObject | BuiltinReceptacle, list[float]]] = [
            *zip(lay["objects"], self._default_poses(lay), strict=True)]
        if self.WITH_RECEPTACLES:
            placed += zip(lay["receptacles"], self._parking_poses(lay), strict=True)
        return placed

    def _parking_poses(self, lay: dict[str, Any]) -> list[list[float]]:
        """Receptacles on the table's side strips, clear of :attr:`REGION_Y` and the default row."""
        y = lay["half_y"] - 0.11
        spots = [(0.38, y), (0.38, -y), (0.6, y)]
        return [[x, sy, lay["height"] + rec.half_extents[2], 1.0, 0.0, 0.0, 0.0]
                for rec, (x, sy) in zip(lay["receptacles"], spots, strict=True)]

    def _default_poses(self, lay: dict[str, Any]) -> list[list[float]]:
        """A row along y near the far table edge, each object resting on the table."""
        objects = lay["objects"]
        ys = np.linspace(-0.25, 0.25, len(objects))
        x = 2 * lay["half_x"] - self.TABLE_BACK - 0.1
        return [[x, float(y), lay["height"] + obj.half_extents[2], 1.0, 0.0, 0.0, 0.0]
                for obj, y in zip(objects, ys, strict=True)]

    def build(self, house_index: int) -> mujoco.MjSpec:
        self.check_house(house_index)
        lay = _layout(house_index)
        world = room_spec(f"{self.name}_{house_index}", lay["floor"])
        wb = world.worldbody
        wb.add_geom(name="wall", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02, 2.5, 1.4], pos=[2.2, 0.0, 1.4],
                    rgba=[*lay["wall"], 1.0], contype=0, conaffinity=0)
        h, hx, hy = lay["height"], lay["half_x"], lay["half_y"]
        cx = hx - self.TABLE_BACK
        table = wb.add_body(name="table", pos=[cx, 0.0, 0.0])
        top = 0.02
        table.add_geom(name="table_top", type=mujoco.mjtGeom.mjGEOM_BOX, size=[hx, hy, top], pos=[0.0, 0.0, h - top],
                       rgba=[*lay["table"], 1.0], friction=[1.0, 0.01, 0.001])
        for sx in (-1, 1):
            for sy in (-1, 1):
                table.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.025, 0.025, (h - 2 * top) / 2],
                               pos=[sx * (hx - 0.05), sy * (hy - 0.05), (h - 2 * top) / 2],
                               rgba=[*lay["table"], 1.0])
        az = lay["light_az"]
        wb.add_light(name="key", pos=[cx - 1.2 * math.cos(az), 1.2 * math.sin(az), h + 1.8],
                     dir=[math.cos(az), -math.sin(az), -1.5], diffuse=[0.7, 0.7, 0.7], castshadow=False)
        wb.add_light(name="fill", pos=[cx, 0.0, h + 2.5], dir=[0.0, 0.0, -1.0], diffuse=[0.3, 0.3, 0.3],
                     castshadow=False)
        for obj, pose in self._placements(lay):
            attach_mjcf(world, obj.mjcf(), obj.uid, pos=pose[:3], quat=pose[3:], source=f"house {house_index}")
        return world


class ProceduralTabletopReceptacles(ProceduralTabletop):
    """The same houses plus three receptacles each (pick-and-place, next-to, color)."""

    name = "procedural_tabletop_receptacles"
    aliases = ()
    WITH_RECEPTACLES = True


@hookimpl
def molmo_scene_datasets() -> list[SceneDataset]:
    return [ProceduralTabletop(), ProceduralTabletopReceptacles()]


@hookimpl
def molmo_asset_libraries() -> list[AssetLibraryType]:
    return [AssetLibraryType("builtin", lambda settings, catalog: [BuiltinAssetLibrary()], priority=300)]
