"""Textured rooms with LIBERO's household objects (``libero_rooms``), a scene plugin.

House ``i`` is drawn from a random stream seeded by ``i`` alone: a room style (kitchen, living
room, study) with its floor, wall and table-top textures and LIBERO's background furniture
(visual meshes only: kitchen cabinets and fridge, a wall unit, shelves, plants, lamps, pictures),
a table (legs, or a counter block in kitchens) of realistic height and size, lights (a key light
that casts shadows, a fill light), and its objects from the ``libero`` asset library
(:mod:`molmo_lerobot.content.libero.objects`): graspable items no two of which share a name and colour (so
"the red ketchup bottle" names one), two flat distractors and three receptacles (two of one kind in
different colours, one of another kind). Every file is read in place from the installed LIBERO
asset distributions.

The robot (``franka_droid``) stands on the floor at the origin facing ``+x``, on MolmoSpaces'
pedestal (its base pose on the floor, the pedestal lifting the arm towards the table), the table's
near edge :data:`TABLE_NEAR` ahead. Default poses rest every object upright on the table top,
clear of each other; episodes place them with ``object_poses``.

The key light casts shadows (a :data:`SHADOW_SIZE` map); the run's render profile
(:mod:`molmo_lerobot.sim.render_profile`) may turn them, reflections and multisampling off and scale
the lights. Textures are read at the profile's size (``MOLMO_SCENE_TEXTURE_SIZE``, default 512).
No debug geometry: collision geoms are in group 3, which cameras never draw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.assets.catalog import AssetLibraryType
from molmo_lerobot.content.libero import install_check
from molmo_lerobot.content.libero.library import LIBERO_LIBRARY_TYPE
from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS, LiberoObject, assets_root, texture_file
from molmo_lerobot.sim.scenes import SceneDataset, attach_mjcf

_SALT = 0x1B3A0
N_HOUSES = 1000
#: the table's near edge ahead of the robot base, and where objects may be placed (robot frame)
TABLE_NEAR = 0.32
REGION_X = (0.42, 0.66)
REGION_Y = (-0.24, 0.24)
#: shadow map resolution
SHADOW_SIZE = 2048
N_GRASPABLE = (4, 6)

_FLOORS = ("light_floor", "gray_floor", "rustic_floor", "seamless_wood_planks_floor", "white_marble_floor",
           "dark_floor_texture", "tile_grigia_caldera_porcelain_floor", "light-gray-floor-tile",
           "gray_ceramic_tile", "brown_ceramic_tile", "dapper_gray_floor")
_WALLS = ("cream-plaster", "gray_plaster", "light_blue_wall", "white_wall", "stucco_wall",
          "yellow_linen_wall_texture", "meeka-beige-plaster", "light-gray-plaster", "smooth_light_gray_plaster",
          "dark_green_plaster_wall")
_TOPS = {"wood": ("martin_novak_wood_table", "table_light_wood", "seamless_wood_planks_floor"),
         "stone": ("white_marble_floor", "marble_floor", "grigia_caldera_porcelain_floor")}


@dataclass(frozen=True)
class Decor:
    """A background mesh of LIBERO's scenes: file, scale, the side it stands against and its yaw there."""

    name: str
    mesh: str  # under assets/scenes/
    texture: str | None
    scale: float
    wall: str  # "back" (+x) or "right" (-y)
    yaw: float  # radians, applied to the mesh as authored
    half_depth: float  # metres from the wall to the mesh centre
    z: float = 0.0


_DECOR = {
    "kitchen": (Decor("kitchen_cabinets", "kitchen_background/visual/kitchen_background_vis.msh",
                      "kitchen_background/kitchen_background.png", 0.01, "back", 0.0, 0.31),
                Decor("fridge", "fridge/visual/fridge_vis.msh", "fridge/metal.png", 0.01, "right", -math.pi / 2, 0.24)),
    "living_room": (Decor("wall_unit", "living_room/visual/living_room_vis.msh",
                           "living_room/living_room_wall_unit.png",
                          0.7, "back", 0.0, 0.2),
                    Decor("plant", "plant/visual/plant_vis.msh", "plant/plant_texture.png", 0.7, "right", 0.0, 0.4),
                    Decor("floor_lamp", "floor_lamp/visual/floor_lamp_vis.msh", "floor_lamp/lamp_texture.png", 1.0,
                          "back", math.pi / 2, 0.5)),
    "study": (Decor("book_shelf", "office_book_shelf/visual/office_book_shelf_vis.msh", "office_book_shelf/ceramic.png",
                    0.7, "back", math.pi / 2, 0.18),
              Decor("painting", "study_wall_painting/visual/study_wall_painting_vis.msh",
                    "study_wall_painting/study_wall_painting.png", 1.0, "right", 0.0, 0.04, 1.0),
              Decor("plant", "plant/visual/plant_vis.msh", "plant/plant_texture.png", 0.7, "right", 0.0, 0.4)),
}
STYLES = tuple(_DECOR)


def _tex(name: str) -> str:
    return str(texture_file(assets_root() / "textures" / f"{name}.png"))


def _by(category_filter) -> list[LiberoObject]:
    return [o for o in LIBERO_OBJECTS.values() if category_filter(o)]


@cache
def _layout(house_index: int) -> dict[str, Any]:
    """Every random choice of a house, drawn in a fixed order."""
    rng = np.random.default_rng([_SALT, house_index])
    style = STYLES[int(rng.integers(len(STYLES)))]
    floor = _FLOORS[int(rng.integers(len(_FLOORS)))]
    wall = _WALLS[int(rng.integers(len(_WALLS)))]
    top_kind = "stone" if style == "kitchen" and rng.random() < 0.6 else "wood"
    top = _TOPS[top_kind][int(rng.integers(len(_TOPS[top_kind])))]
    height = float(rng.uniform(0.72, 0.78))
    depth = float(rng.uniform(0.75, 0.95))
    half_y = float(rng.uniform(0.6, 0.85))
    back_gap = float(rng.uniform(0.45, 0.9))
    side_gap = float(rng.uniform(0.5, 1.0))
    decor_y = float(rng.uniform(-0.4, 0.4))
    light_az = float(rng.uniform(-math.pi / 3, math.pi / 3))
    graspable = [o for o in _by(lambda o: o.graspable)]
    chosen: list[LiberoObject] = []
    n = int(rng.integers(N_GRASPABLE[0], N_GRASPABLE[1] + 1))
    for k in rng.permutation(len(graspable)):
        obj = graspable[int(k)]
        if all((o.name, o.color) != (obj.name, obj.color) for o in chosen):
            chosen.append(obj)
        if len(chosen) == n:
            break
    flat = _by(lambda o: not o.graspable and not o.receptacle)
    distractors = [flat[int(k)] for k in rng.choice(len(flat), 2, replace=False)]
    return {"style": style, "floor": floor, "wall": wall, "top_kind": top_kind, "top": top, "height": height,
            "depth": depth, "half_y": half_y, "back_gap": back_gap, "side_gap": side_gap, "decor_y": decor_y,
            "light_az": light_az, "objects": chosen, "distractors": distractors, "receptacles": _receptacles(rng)}


def _receptacles(rng: np.random.Generator) -> list[LiberoObject]:
    """Two receptacles of one category (different colours) and one of another category."""
    by_category: dict[str, list[LiberoObject]] = {}
    for obj in _by(lambda o: o.receptacle):
        by_category.setdefault(obj.category, []).append(obj)
    pairs = sorted(c for c, objs in by_category.items() if len({o.color for o in objs}) >= 2)
    first = pairs[int(rng.integers(len(pairs)))]
    pair = [by_category[first][int(k)] for k in rng.choice(len(by_category[first]), 2, replace=False)]
    others = sorted(c for c in by_category if c != first)
    second = by_category[others[int(rng.integers(len(others)))]]
    return [*pair, second[int(rng.integers(len(second)))]]


def resting_radius(obj: LiberoObject) -> float:
    """Radius of the object's footprint on the table (any yaw)."""
    hx, hy, _ = obj.half_extents
    return math.hypot(hx, hy)


def referring_expression(obj: LiberoObject, others: list[LiberoObject]) -> str:
    """The shortest of "the <name>", "the <colour> <name>", "the <colour> <material> <name>" that no
    other object of ``others`` also fits (MolmoSpaces' colour/material referring expressions)."""
    for words in (obj.name, obj.colored_name, obj.description):
        clash = [o for o in others if o.uid != obj.uid and words in (o.name, o.colored_name, o.description)]
        if not clash:
            return f"the {words}"
    raise ValueError(f"no referring expression tells {obj.uid!r} apart from {[o.uid for o in others]}")


class LiberoRooms(SceneDataset):
    """Textured rooms with LIBERO objects on a table in front of franka_droid (module docstring)."""

    name = "libero_rooms"
    aliases = ()

    def install_problem(self) -> str | None:
        """A broken file of the installed LIBERO asset library (:mod:`molmo_lerobot.content.libero.install_check`)."""
        return install_check.install_problem()

    def n_houses(self) -> int:
        return N_HOUSES

    def objects(self, house_index: int) -> list[LiberoObject]:
        """The house's objects: graspable items, distractors, receptacles (in that order)."""
        lay = _layout(house_index)
        return [*lay["objects"], *lay["distractors"], *lay["receptacles"]]

    def metadata(self, house_index: int) -> dict[str, Any]:
        self.check_house(house_index)
        lay = _layout(house_index)
        objects = self.objects(house_index)
        return {
            "scene_dataset": self.name,
            "house_index": house_index,
            "style": lay["style"],
            "textures": {"floor": lay["floor"], "wall": lay["wall"], "table": lay["top"]},
            "table_height": lay["height"],
            "table_extent": {"x": [TABLE_NEAR, TABLE_NEAR + lay["depth"]], "y": [-lay["half_y"], lay["half_y"]]},
            "robot_base_pose": [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            "placement_region": {"x": list(REGION_X), "y": list(REGION_Y), "z": lay["height"]},
            "objects": {
                obj.uid: {"asset_id": obj.uid, "category": obj.category, "name": obj.name, "color": obj.color,
                          "material": obj.material, "description": obj.description,
                          "referring_expression": referring_expression(obj, objects), "default_pose": pose,
                          "receptacle": obj.receptacle, "graspable": obj.graspable}
                for obj, pose in zip(objects, _default_poses(house_index), strict=True)
            },
        }

    def build(self, house_index: int) -> mujoco.MjSpec:
        self.check_house(house_index)
        lay = _layout(house_index)
        world = mujoco.MjSpec()
        world.modelname = f"{self.name}_{house_index}"
        world.visual.headlight.ambient = [0.25, 0.25, 0.25]
        world.visual.headlight.diffuse = [0.25, 0.25, 0.25]
        world.visual.headlight.specular = [0.0, 0.0, 0.0]
        world.visual.quality.shadowsize = SHADOW_SIZE
        h, depth, hy = lay["height"], lay["depth"], lay["half_y"]
        far = TABLE_NEAR + depth
        back = far + lay["back_gap"]
        right = -(hy + lay["side_gap"])
        left = hy + lay["side_gap"] + 0.6
        behind = -1.4
        self._room(world, lay, back, right, left, behind)
        self._table(world, lay)
        for decor in _DECOR[lay["style"]]:
            self._decor(world, decor, back, right, lay["decor_y"])
        cx = TABLE_NEAR + depth / 2
        az = lay["light_az"]
        world.worldbody.add_light(name="key", pos=[cx - 0.9 * math.cos(az), 0.9 * math.sin(az), h + 1.9],
                                  dir=[0.9 * math.cos(az), -0.9 * math.sin(az), -1.9], diffuse=[0.75] * 3,
                                  specular=[0.2] * 3, castshadow=True, cutoff=55.0, exponent=2.0,
                                  type=mujoco.mjtLightType.mjLIGHT_SPOT)
        world.worldbody.add_light(name="fill", pos=[cx, 0.0, 2.6], dir=[0.0, 0.0, -1.0], diffuse=[0.3] * 3,
                                  specular=[0.0] * 3, castshadow=False, type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
        for obj, pose in zip(self.objects(house_index), _default_poses(house_index), strict=True):
            attach_mjcf(world, obj.mjcf(), obj.uid, pos=pose[:3], quat=pose[3:], source=f"house {house_index}")
        return world

    # Parts -------------------------------------------------------------------------------------
    @staticmethod
    def _material(world: mujoco.MjSpec, name: str, texture: str, repeat: tuple[float, float], uniform: bool,
                  specular: float = 0.1, shininess: float = 0.1, reflectance: float = 0.0) -> str:
        world.add_texture(name=f"tex_{name}", type=mujoco.mjtTexture.mjTEXTURE_2D, file=_tex(texture))
        mat = world.add_material(name=name, texrepeat=list(repeat), texuniform=uniform, specular=specular,
                                 shininess=shininess, reflectance=reflectance)
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"tex_{name}"
        return name

    def _room(self, world: mujoco.MjSpec, lay: dict[str, Any], back: float, right: float, left: float,
              behind: float) -> None:
        wb = world.worldbody
        floor = self._material(world, "floor", lay["floor"], (0.8, 0.8), True)
        walls = self._material(world, "walls", lay["wall"], (0.5, 0.5), True, specular=0.05)
        cx, cy = (back + behind) / 2, (left + right) / 2
        wb.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE,
                size=[(back - behind) / 2, (left - right) / 2, 0.05],
                    pos=[cx, cy, 0.0], material=floor, friction=[1.0, 0.01, 0.001])
        height = 2.6
        for name, pos, size in (("wall_back", [back + 0.02, cy, height / 2], [0.02, (left - right) / 2, height / 2]),
                                ("wall_behind", [behind - 0.02, cy, height / 2],
                                 [0.02, (left - right) / 2, height / 2]),
                                ("wall_right", [cx, right - 0.02, height / 2], [(back - behind) / 2, 0.02, height / 2]),
                                ("wall_left", [cx, left + 0.02, height / 2], [(back - behind) / 2, 0.02, height / 2])):
            wb.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=pos, size=size, material=walls,
                        contype=0, conaffinity=0)

    def _table(self, world: mujoco.MjSpec, lay: dict[str, Any]) -> None:
        h, depth, hy = lay["height"], lay["depth"], lay["half_y"]
        top_mat = self._material(world, "table_top", lay["top"], (1.0, 1.0), True, specular=0.3, shininess=0.4,
                                 reflectance=0.05 if lay["top_kind"] == "stone" else 0.0)
        table = world.worldbody.add_body(name="table", pos=[TABLE_NEAR + depth / 2, 0.0, 0.0])
        thick = 0.03
        table.add_geom(name="table_top", type=mujoco.mjtGeom.mjGEOM_BOX, size=[depth / 2, hy, thick / 2],
                       pos=[0.0, 0.0, h - thick / 2], material=top_mat, friction=[1.0, 0.01, 0.001])
        if lay["style"] == "kitchen":  # a counter: cabinets under the top, set back a little
            body_mat = self._material(world, "counter", "table_light_wood", (1.0, 1.0), True)
            table.add_geom(name="counter_body", type=mujoco.mjtGeom.mjGEOM_BOX,
                           size=[depth / 2 - 0.04, hy - 0.02, (h - thick) / 2], pos=[0.02, 0.0, (h - thick) / 2],
                           material=body_mat)
            return
        for sx in (-1, 1):
            for sy in (-1, 1):
                table.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.03, 0.03, (h - thick) / 2],
                               pos=[sx * (depth / 2 - 0.06), sy * (hy - 0.06), (h - thick) / 2], material=top_mat)

    def _decor(self, world: mujoco.MjSpec, decor: Decor, back: float, right: float, offset: float) -> None:
        root = assets_root() / "scenes"
        mesh = world.add_mesh(name=f"decor_{decor.name}", file=str(root / decor.mesh), scale=[decor.scale] * 3)
        attrs: dict[str, Any] = {}
        if decor.texture:
            world.add_texture(name=f"tex_decor_{decor.name}", type=mujoco.mjtTexture.mjTEXTURE_2D,
                              file=str(texture_file(root / decor.texture)))
            mat = world.add_material(name=f"decor_{decor.name}", specular=0.2, shininess=0.2)
            mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"tex_decor_{decor.name}"
            attrs["material"] = mat.name
        if decor.wall == "back":
            pos, yaw = [back - decor.half_depth, offset, decor.z], decor.yaw
        else:
            pos, yaw = [TABLE_NEAR + 0.6 + offset, right + decor.half_depth, decor.z], decor.yaw + math.pi / 2
        world.worldbody.add_geom(name=f"decor_{decor.name}", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mesh.name,
                                 pos=pos, quat=[math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)], contype=0,
                                 conaffinity=0, group=1, **attrs)


@cache
def _default_poses(house_index: int) -> list[list[float]]:
    """Objects upright on the table top, clear of each other: receptacles and distractors along the
    far and side edges, graspable items in a row behind the placement region."""
    lay = _layout(house_index)
    rng = np.random.default_rng([_SALT, house_index, 1])
    objects = [*lay["objects"], *lay["distractors"], *lay["receptacles"]]
    far = TABLE_NEAR + lay["depth"]
    x_lo, x_hi = TABLE_NEAR + 0.08, far - 0.08
    y_lo, y_hi = -lay["half_y"] + 0.08, lay["half_y"] - 0.08
    placed: list[tuple[float, float, float]] = []
    poses: dict[str, list[float]] = {}
    for obj in sorted(objects, key=resting_radius, reverse=True):  # the largest first
        r = resting_radius(obj)
        # outside the placement region if there is room, else anywhere, else footprint circles may touch
        for attempt in range(1500):
            x, y = float(rng.uniform(x_lo + r, x_hi - r)), float(rng.uniform(y_lo + r, y_hi - r))
            in_region = REGION_X[0] - r < x < REGION_X[1] + r and REGION_Y[0] - r < y < REGION_Y[1] + r
            gap = 0.02 if attempt < 1000 else -0.02
            if (attempt >= 500 or not in_region) and all(math.hypot(x - px, y - py) >= r + pr + gap
                                                         for px, py, pr in placed):
                break
        else:
            raise RuntimeError(f"libero_rooms house {house_index}: no room on the table for {obj.uid}")
        placed.append((x, y, r))
        yaw = float(rng.uniform(-math.pi, math.pi))
        poses[obj.uid] = [round(x, 5), round(y, 5), round(lay["height"] + obj.half_extents[2] + 0.001, 5),
                          round(math.cos(yaw / 2), 5), 0.0, 0.0, round(math.sin(yaw / 2), 5)]
    return [poses[obj.uid] for obj in objects]


@hookimpl
def molmo_scene_datasets() -> list[SceneDataset]:
    return [LiberoRooms()]


@hookimpl
def molmo_asset_libraries() -> list[AssetLibraryType]:
    return [LIBERO_LIBRARY_TYPE]
