"""Small multi-room houses for navigation (``nav_houses``), a scene plugin.

House ``i`` is drawn from a random stream seeded by ``i`` alone: a grid of 2×1 to 3×2 rooms
(3.2–4.2 m by 3.0–4.0 m each) inside outer walls, every pair of neighbouring rooms joined by a
doorway (:data:`DOOR_WIDTH` wide, a lintel above it) in the wall between them; floor and wall
textures from LIBERO's scene textures; in every room two or three pieces of furniture standing
against its walls, clear of the doorways (tables on legs, cabinets, sideboards, textured with
LIBERO's wood and stone); and :data:`N_OBJECTS` of LIBERO's household objects
(:mod:`molmo_lerobot.content.libero.objects`) standing upright on the furniture tops, from categories of
which two have two instances each (in different rooms where the furniture allows), so that "any
bowl" has candidates. Every file is read in place from the installed LIBERO asset distributions.

Walls and furniture collide (group 0 visual + collision in one geom: boxes); the floor spans the
house. The metadata lists the rooms, doorways, furniture and objects (with their categories, the
room they are in and their resting poses) and a default ``robot_base_pose`` in the first room.
No robot is placed here: episodes put ``mobile_franka`` at ``task.robot_base_pose``.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.content.libero import install_check
from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS, LiberoObject, assets_root, texture_file
from molmo_lerobot.sim.scenes import SceneDataset, attach_mjcf

_SALT = 0x4E4156
N_HOUSES = 1000
WALL_HEIGHT, WALL_THICK = 2.5, 0.1
DOOR_WIDTH, DOOR_HEIGHT = 1.4, 2.1
N_OBJECTS = 6
#: free floor kept in front of a doorway (m into each room) and between pieces of furniture
DOOR_CLEARANCE, FURNITURE_GAP = 1.1, 0.5
_FLOORS = ("light_floor", "gray_floor", "rustic_floor", "seamless_wood_planks_floor", "white_marble_floor",
           "dark_floor_texture", "light-gray-floor-tile", "gray_ceramic_tile", "brown_ceramic_tile")
_WALLS = ("cream-plaster", "gray_plaster", "light_blue_wall", "white_wall", "stucco_wall",
          "yellow_linen_wall_texture", "meeka-beige-plaster", "light-gray-plaster", "dark_green_plaster_wall")
_WOODS = ("martin_novak_wood_table", "table_light_wood", "seamless_wood_planks_floor")
_STONES = ("white_marble_floor", "marble_floor", "grigia_caldera_porcelain_floor")
#: furniture kinds: (x size range, y size range, height range) in metres (x along the wall)
_FURNITURE = {"table": ((1.0, 1.4), (0.6, 0.8), (0.72, 0.78)),
              "cabinet": ((0.8, 1.2), (0.45, 0.55), (0.85, 0.92)),
              "sideboard": ((1.2, 1.6), (0.4, 0.5), (0.6, 0.7))}


def _tex(name: str) -> str:
    return str(texture_file(assets_root() / "textures" / f"{name}.png"))


def _category_objects() -> dict[str, list[LiberoObject]]:
    """LIBERO objects by category, those big enough to be seen across a room (any side over 5 cm)."""
    out: dict[str, list[LiberoObject]] = {}
    for obj in LIBERO_OBJECTS.values():
        if max(obj.half_extents) * 2 >= 0.1:
            out.setdefault(obj.category, []).append(obj)
    return out


def display_name(category: str) -> str:
    """How a prompt names a category (``soup_can`` -> ``soup can``)."""
    return category.replace("_", " ")


@cache
def layout(house_index: int) -> dict[str, Any]:
    """Every choice of a house, drawn in a fixed order: rooms, doorways, textures, furniture, objects."""
    rng = np.random.default_rng([_SALT, house_index])
    nx, ny = [(2, 1), (3, 1), (2, 2), (3, 2)][int(rng.integers(4))]
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(3.2, 4.2, nx))])
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(3.0, 4.0, ny))])
    rooms = [{"index": k, "x": [float(xs[i]), float(xs[i + 1])], "y": [float(ys[j]), float(ys[j + 1])]}
             for k, (i, j) in enumerate((i, j) for j in range(ny) for i in range(nx))]
    doors = []  # {"axis": "x"|"y" (the wall's normal), "at": wall coordinate, "centre": along the wall}
    for j in range(ny):
        for i in range(1, nx):
            lo, hi = ys[j] + 0.35 + DOOR_WIDTH / 2, ys[j + 1] - 0.35 - DOOR_WIDTH / 2
            doors.append({"axis": "x", "at": float(xs[i]), "centre": float(rng.uniform(lo, hi))})
    for i in range(nx):
        for j in range(1, ny):
            lo, hi = xs[i] + 0.35 + DOOR_WIDTH / 2, xs[i + 1] - 0.35 - DOOR_WIDTH / 2
            doors.append({"axis": "y", "at": float(ys[j]), "centre": float(rng.uniform(lo, hi))})
    floor = _FLOORS[int(rng.integers(len(_FLOORS)))]
    wall = _WALLS[int(rng.integers(len(_WALLS)))]
    furniture: list[dict] = []
    for room in rooms:
        for _ in range(int(rng.integers(2, 4))):
            piece = _place_furniture(rng, room, doors, furniture)
            if piece is not None:
                furniture.append(piece)
    objects = _place_objects(rng, rooms, furniture)
    return {"rooms": rooms, "doors": doors, "floor": floor, "wall": wall, "furniture": furniture,
            "objects": objects, "size": [float(xs[-1]), float(ys[-1])]}


def _door_zones(doors: list[dict[str, Any]]) -> list[tuple[float, float, float, float]]:
    """Floor rectangles (xmin, ymin, xmax, ymax) kept free in front of every doorway, both sides."""
    out = []
    for d in doors:
        half = DOOR_WIDTH / 2 + 0.2
        if d["axis"] == "x":
            out.append((d["at"] - DOOR_CLEARANCE, d["centre"] - half, d["at"] + DOOR_CLEARANCE, d["centre"] + half))
        else:
            out.append((d["centre"] - half, d["at"] - DOOR_CLEARANCE, d["centre"] + half, d["at"] + DOOR_CLEARANCE))
    return out


def _overlap(a: tuple[float, ...], b: tuple[float, ...], gap: float = 0.0) -> bool:
    return a[0] < b[2] + gap and b[0] < a[2] + gap and a[1] < b[3] + gap and b[1] < a[3] + gap


def _place_furniture(rng: np.random.Generator, room: dict[str, Any], doors: list[dict[str, Any]],
                     placed: list[dict[str, Any]]) -> dict[str, Any] | None:
    """A piece against one of the room's walls, clear of doorways and other pieces (None after 40 draws)."""
    kind = ("table", "cabinet", "sideboard")[int(rng.integers(3))]
    (lx0, lx1), (ly0, ly1), (h0, h1) = _FURNITURE[kind]
    length, depth, height = float(rng.uniform(lx0, lx1)), float(rng.uniform(ly0, ly1)), float(rng.uniform(h0, h1))
    material = (_STONES if kind == "cabinet" and rng.random() < 0.4 else _WOODS)
    texture = material[int(rng.integers(len(material)))]
    (x0, x1), (y0, y1) = room["x"], room["y"]
    inset = WALL_THICK / 2 + 0.02
    zones = _door_zones(doors)
    for _ in range(40):
        side = int(rng.integers(4))  # 0: wall at y0, 1: at y1, 2: at x0, 3: at x1
        if side < 2:
            cx = float(rng.uniform(x0 + inset + length / 2, x1 - inset - length / 2))
            cy = y0 + inset + depth / 2 if side == 0 else y1 - inset - depth / 2
            hx, hy = length / 2, depth / 2
        else:
            cy = float(rng.uniform(y0 + inset + length / 2, y1 - inset - length / 2))
            cx = x0 + inset + depth / 2 if side == 2 else x1 - inset - depth / 2
            hx, hy = depth / 2, length / 2
        box = (cx - hx, cy - hy, cx + hx, cy + hy)
        if any(_overlap(box, z) for z in zones) or any(_overlap(box, tuple(p["box"]), FURNITURE_GAP) for p in placed):
            continue
        return {"name": f"furniture_{len(placed)}", "kind": kind, "room": room["index"],
                "box": [round(v, 5) for v in box], "height": round(height, 5), "texture": texture}
    return None


def _place_objects(rng: np.random.Generator, rooms: list[dict[str, Any]],
                   furniture: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """:data:`N_OBJECTS` objects on furniture tops: two categories twice (different rooms), the rest once."""
    by_category = _category_objects()
    pairs = sorted(c for c, objs in by_category.items() if len(objs) >= 2)
    singles = sorted(by_category)
    chosen: list[LiberoObject] = []
    for c in rng.choice(len(pairs), 2, replace=False):
        objs = by_category[pairs[int(c)]]
        chosen += [objs[int(k)] for k in rng.choice(len(objs), 2, replace=False)]
    rest = [c for c in singles if c not in {o.category for o in chosen}]
    for c in rng.choice(len(rest), N_OBJECTS - len(chosen), replace=False):
        objs = by_category[rest[int(c)]]
        chosen.append(objs[int(rng.integers(len(objs)))])
    out: list[dict[str, Any]] = []
    used: dict[str, list[tuple[float, float, float]]] = {}
    for obj in chosen:
        same = [o["room"] for o in out if LIBERO_OBJECTS[o["uid"]].category == obj.category]
        spots = [p for p in furniture if p["room"] not in same] or furniture
        r = math.hypot(*obj.half_extents[:2])
        for _ in range(60):
            piece = spots[int(rng.integers(len(spots)))]
            x0, y0, x1, y1 = piece["box"]
            if x1 - x0 < 2 * r + 0.16 or y1 - y0 < 2 * r + 0.16:
                continue
            x, y = float(rng.uniform(x0 + r + 0.08, x1 - r - 0.08)), float(rng.uniform(y0 + r + 0.08, y1 - r - 0.08))
            if all(math.hypot(x - px, y - py) >= r + pr + 0.05 for px, py, pr in used.get(piece["name"], [])):
                break
        else:
            raise RuntimeError(f"nav_houses: no room on the furniture for {obj.uid}")
        used.setdefault(piece["name"], []).append((x, y, r))
        yaw = float(rng.uniform(-math.pi, math.pi))
        pose = [x, y, piece["height"] + obj.half_extents[2] + 0.002, math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        out.append({"uid": obj.uid, "room": piece["room"], "on": piece["name"], "pose": [round(v, 5) for v in pose]})
    return out


class NavHouses(SceneDataset):
    """Multi-room houses with furniture and LIBERO objects for ``nav_to_obj`` (module docstring)."""

    name = "nav_houses"

    def install_problem(self) -> str | None:
        """A broken file of the installed LIBERO asset library (:mod:`molmo_lerobot.content.libero.install_check`)."""
        return install_check.install_problem()

    def n_houses(self) -> int:
        return N_HOUSES

    def metadata(self, house_index: int) -> dict[str, Any]:
        self.check_house(house_index)
        lay = layout(house_index)
        first = lay["rooms"][0]
        return {
            "scene_dataset": self.name,
            "house_index": house_index,
            "size": lay["size"],
            "rooms": lay["rooms"],
            "doors": lay["doors"],
            "textures": {"floor": lay["floor"], "wall": lay["wall"]},
            "furniture": lay["furniture"],
            "robot_base_pose": [sum(first["x"]) / 2, sum(first["y"]) / 2, 0.005, 1.0, 0.0, 0.0, 0.0],
            "objects": {
                o["uid"]: {"asset_id": o["uid"], "category": LIBERO_OBJECTS[o["uid"]].category,
                           "name": LIBERO_OBJECTS[o["uid"]].name, "room": o["room"], "on": o["on"],
                           "default_pose": o["pose"]}
                for o in lay["objects"]
            },
        }

    def build(self, house_index: int) -> mujoco.MjSpec:
        self.check_house(house_index)
        lay = layout(house_index)
        world = mujoco.MjSpec()
        world.modelname = f"{self.name}_{house_index}"
        world.visual.headlight.ambient = [0.35, 0.35, 0.35]
        world.visual.headlight.diffuse = [0.35, 0.35, 0.35]
        world.visual.headlight.specular = [0.0, 0.0, 0.0]
        sx, sy = lay["size"]
        floor = _material(world, "floor", lay["floor"], (0.8, 0.8))
        walls = _material(world, "walls", lay["wall"], (0.5, 0.5))
        world.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, material=floor,
                                 size=[sx / 2 + 0.5, sy / 2 + 0.5, 0.05], pos=[sx / 2, sy / 2, 0.0])
        self._walls(world, lay, walls)
        for piece in lay["furniture"]:
            self._furniture(world, piece)
        world.worldbody.add_light(name="sun", pos=[sx / 2, sy / 2, 6.0], dir=[0.3, 0.2, -1.0], diffuse=[0.5] * 3,
                                  specular=[0.0] * 3, castshadow=False, type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
        for o in lay["objects"]:
            attach_mjcf(world, LIBERO_OBJECTS[o["uid"]].mjcf(), o["uid"], pos=o["pose"][:3], quat=o["pose"][3:],
                        source=f"house {house_index}")
        return world

    @staticmethod
    def _walls(world: mujoco.MjSpec, lay: dict[str, Any], material: str) -> None:
        """Outer walls, and the walls between rooms with their doorways (and lintels above them)."""
        sx, sy = lay["size"]
        xs = sorted({r["x"][0] for r in lay["rooms"]} | {r["x"][1] for r in lay["rooms"]})
        ys = sorted({r["y"][0] for r in lay["rooms"]} | {r["y"][1] for r in lay["rooms"]})
        segments: list[tuple[str, float, float, float, float | None]] = [  # axis, at, from, to, door centre
            ("y", 0.0, 0.0, sx, None), ("y", sy, 0.0, sx, None), ("x", 0.0, 0.0, sy, None), ("x", sx, 0.0, sy, None)]
        for d in lay["doors"]:
            along = ys if d["axis"] == "x" else xs
            lo = max(v for v in along if v < d["centre"])
            hi = min(v for v in along if v > d["centre"])
            segments.append((d["axis"], d["at"], lo, hi, d["centre"]))
        wb = world.worldbody
        for k, (axis, at, lo, hi, door) in enumerate(segments):
            pieces = [(lo, hi, 0.0, WALL_HEIGHT)]
            if door is not None:
                a, b = door - DOOR_WIDTH / 2, door + DOOR_WIDTH / 2
                pieces = [(lo, a, 0.0, WALL_HEIGHT), (b, hi, 0.0, WALL_HEIGHT), (a, b, DOOR_HEIGHT, WALL_HEIGHT)]
            for n, (p0, p1, z0, z1) in enumerate(pieces):
                half_len = (p1 - p0) / 2 + (WALL_THICK / 2 if door is None else 0.0)
                centre = (p0 + p1) / 2
                pos = [at, centre, (z0 + z1) / 2] if axis == "x" else [centre, at, (z0 + z1) / 2]
                size = [WALL_THICK / 2, half_len, (z1 - z0) / 2] if axis == "x" else [half_len, WALL_THICK / 2,
                                                                                      (z1 - z0) / 2]
                wb.add_geom(name=f"wall_{k}_{n}", type=mujoco.mjtGeom.mjGEOM_BOX, pos=pos, size=size, material=material)

    @staticmethod
    def _furniture(world: mujoco.MjSpec, piece: dict[str, Any]) -> None:
        x0, y0, x1, y1 = piece["box"]
        h = piece["height"]
        mat = _material(world, piece["name"], piece["texture"], (1.0, 1.0), specular=0.3)
        body = world.worldbody.add_body(name=piece["name"], pos=[(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
        hx, hy = (x1 - x0) / 2, (y1 - y0) / 2
        if piece["kind"] != "table":
            body.add_geom(name=f"{piece['name']}/body", type=mujoco.mjtGeom.mjGEOM_BOX, size=[hx, hy, h / 2],
                          pos=[0.0, 0.0, h / 2], material=mat)
            return
        thick = 0.04
        body.add_geom(name=f"{piece['name']}/top", type=mujoco.mjtGeom.mjGEOM_BOX, size=[hx, hy, thick / 2],
                      pos=[0.0, 0.0, h - thick / 2], material=mat)
        for sx in (-1, 1):
            for sy in (-1, 1):
                body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.03, 0.03, (h - thick) / 2],
                              pos=[sx * (hx - 0.05), sy * (hy - 0.05), (h - thick) / 2], material=mat)


def _material(world: mujoco.MjSpec, name: str, texture: str, repeat: tuple[float, float],
              specular: float = 0.05) -> str:
    if world.texture(f"tex_{texture}") is None:  # one texture per file, shared by materials
        world.add_texture(name=f"tex_{texture}", type=mujoco.mjtTexture.mjTEXTURE_2D, file=_tex(texture))
    mat = world.add_material(name=f"mat_{name}", texrepeat=list(repeat), texuniform=True, specular=specular)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"tex_{texture}"
    return mat.name


@hookimpl
def molmo_scene_datasets() -> list[SceneDataset]:
    return [NavHouses()]
