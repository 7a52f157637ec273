"""Two rooms joined by a hinged door (``door_rooms``), a scene plugin.

House ``i`` is drawn from a random stream seeded by ``i`` alone. A wall along the plane ``x = 0``
(:data:`WALL_THICKNESS` thick, colliding) divides two rooms; a doorway in it, :data:`DOOR_HEIGHT`
high and 0.86–1.0 m wide, holds a door leaf on a latch-free hinge (damping and friction only, no
spring and no latch, range ``[0, DOOR_RANGE]`` with 0 closed and positive angles opening). The
hinge is on either jamb and the door swings into either room; a vertical bar handle stands on each
face, 0.95–1.05 m high, near the free edge. Floor, walls and door leaf are textured with the
installed LIBERO textures (read in place, as :mod:`molmo_lerobot.content.libero.rooms` reads them).

Body names, in MolmoSpaces' door layout (their ``Door`` data view reads the same tree): ``door``
(the frame, static) → ``door/leaf`` (joint ``door/hinge``) → the handles ``door/handle_pos`` (on
the ``+x`` face) and ``door/handle_neg`` (``-x``), the leaves of the tree, each with one visual geom
(no contacts, group 2) and collision geoms in group 3, which cameras never draw.

``metadata(i)["door"]`` gives the geometry experts and generators need: hinge position, the side
the leaf extends to from the hinge (``leaf_dir``, ±1 along y), the room it swings into
(``swing_side``, ±1 along x), leaf width, handle height and the doorway's y extent.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.content.libero import install_check
from molmo_lerobot.content.libero.objects import assets_root, texture_file
from molmo_lerobot.sim.scenes import SceneDataset

_SALT = 0xD0025
N_HOUSES = 1000
DOOR_NAME = "door"
HINGE_JOINT = "door/hinge"
DOOR_HEIGHT = 2.05
DOOR_RANGE = math.pi / 2
WALL_THICKNESS = 0.10
LEAF_THICKNESS = 0.04
#: how far each room reaches from the wall, and the rooms' half width along y
ROOM_DEPTH, ROOM_HALF_Y = 3.5, 3.0
ROOM_HEIGHT = 2.6
#: handle bar: radius, half length, distance from the leaf face, distance from the free edge
HANDLE_RADIUS, HANDLE_HALF_LEN, HANDLE_OFF, HANDLE_INSET = 0.014, 0.09, 0.06, 0.08
SHADOW_SIZE = 2048

_FLOORS = ("light_floor", "gray_floor", "rustic_floor", "seamless_wood_planks_floor", "white_marble_floor",
           "dark_floor_texture", "light-gray-floor-tile", "gray_ceramic_tile", "brown_ceramic_tile",
           "dapper_gray_floor")
_WALLS = ("cream-plaster", "gray_plaster", "light_blue_wall", "white_wall", "stucco_wall",
          "yellow_linen_wall_texture", "meeka-beige-plaster", "light-gray-plaster", "smooth_light_gray_plaster",
          "dark_green_plaster_wall")
_LEAVES = ("martin_novak_wood_table", "table_light_wood", "seamless_wood_planks_floor", "white_wall", "gray_plaster")
_HANDLE_RGBA = ((0.75, 0.75, 0.78, 1.0), (0.2, 0.2, 0.22, 1.0), (0.72, 0.58, 0.3, 1.0))


@cache
def layout(house_index: int) -> dict[str, Any]:
    """Every random choice of a house, drawn in a fixed order."""
    rng = np.random.default_rng([_SALT, house_index])
    width = float(rng.uniform(0.86, 1.0))
    y0 = float(rng.uniform(-0.6, 0.6)) - width / 2  # the doorway's low-y jamb
    leaf_dir = 1 if rng.random() < 0.5 else -1  # hinge on the low-y jamb, leaf towards +y (or the reverse)
    swing_side = 1 if rng.random() < 0.5 else -1
    return {
        "width": width, "y0": y0, "leaf_dir": leaf_dir, "swing_side": swing_side,
        "handle_z": float(rng.uniform(0.95, 1.05)),
        "damping": float(rng.uniform(2.0, 4.0)), "frictionloss": float(rng.uniform(1.0, 2.5)),
        "floor": _FLOORS[int(rng.integers(len(_FLOORS)))], "walls": _WALLS[int(rng.integers(len(_WALLS)))],
        "leaf": _LEAVES[int(rng.integers(len(_LEAVES)))],
        "handle_rgba": _HANDLE_RGBA[int(rng.integers(len(_HANDLE_RGBA)))],
        "light_az": float(rng.uniform(-math.pi, math.pi)),
    }


def door_geometry(house_index: int) -> dict[str, Any]:
    """The door's geometry in world coordinates (JSON-ready; see the module docstring)."""
    lay = layout(house_index)
    gap = 0.01
    hinge_y = lay["y0"] + gap if lay["leaf_dir"] > 0 else lay["y0"] + lay["width"] - gap
    leaf_width = lay["width"] - 2 * gap
    return {"body": DOOR_NAME, "hinge_joint": HINGE_JOINT, "hinge": [0.0, hinge_y, 0.0], "leaf_dir": lay["leaf_dir"],
            "swing_side": lay["swing_side"], "leaf_width": leaf_width, "handle_z": lay["handle_z"],
            "handle_radius": leaf_width - HANDLE_INSET, "handle_offset": LEAF_THICKNESS / 2 + HANDLE_OFF,
            "doorway_y": [lay["y0"], lay["y0"] + lay["width"]], "range": [0.0, DOOR_RANGE],
            "wall_half_thickness": WALL_THICKNESS / 2}


def _material(world: mujoco.MjSpec, name: str, texture: str, repeat: tuple[float, float], uniform: bool,
              specular: float = 0.1) -> str:
    world.add_texture(name=f"tex_{name}", type=mujoco.mjtTexture.mjTEXTURE_2D,
                      file=str(texture_file(assets_root() / "textures" / f"{texture}.png")))
    mat = world.add_material(name=name, texrepeat=list(repeat), texuniform=uniform, specular=specular, shininess=0.1)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"tex_{name}"
    return name


class DoorRooms(SceneDataset):
    """Two rooms and a hinged door between them (module docstring)."""

    name = "door_rooms"
    aliases = ()

    def install_problem(self) -> str | None:
        """A broken file of the installed LIBERO asset library (:mod:`molmo_lerobot.content.libero.install_check`)."""
        return install_check.install_problem()

    def n_houses(self) -> int:
        return N_HOUSES

    def metadata(self, house_index: int) -> dict[str, Any]:
        self.check_house(house_index)
        lay = layout(house_index)
        door = door_geometry(house_index)
        return {
            "scene_dataset": self.name,
            "house_index": house_index,
            "textures": {"floor": lay["floor"], "walls": lay["walls"], "door": lay["leaf"]},
            "door": door,
            "room_extent": {"x": [-ROOM_DEPTH, ROOM_DEPTH], "y": [-ROOM_HALF_Y, ROOM_HALF_Y]},
            "objects": {DOOR_NAME: {"asset_id": DOOR_NAME, "category": "Doorway", "articulated": True,
                                    "joints": {"hinge": {"joint": HINGE_JOINT, "body": f"{DOOR_NAME}/leaf",
                                                         "type": "hinge", "closed": 0.0, "open": DOOR_RANGE}}}},
        }

    def build(self, house_index: int) -> mujoco.MjSpec:
        self.check_house(house_index)
        lay = layout(house_index)
        door = door_geometry(house_index)
        world = mujoco.MjSpec()
        world.modelname = f"{self.name}_{house_index}"
        world.compiler.degree = False  # the hinge range is in radians
        world.visual.headlight.ambient = [0.3, 0.3, 0.3]
        world.visual.headlight.diffuse = [0.3, 0.3, 0.3]
        world.visual.headlight.specular = [0.0, 0.0, 0.0]
        world.visual.quality.shadowsize = SHADOW_SIZE
        self._rooms(world, lay)
        self._door(world, lay, door)
        az = lay["light_az"]
        world.worldbody.add_light(name="key", pos=[1.5 * math.cos(az), 1.5 * math.sin(az), 2.4],
                                  dir=[-math.cos(az), -math.sin(az), -1.6], diffuse=[0.6] * 3, specular=[0.1] * 3,
                                  castshadow=True, cutoff=70.0, type=mujoco.mjtLightType.mjLIGHT_SPOT)
        world.worldbody.add_light(name="fill", pos=[0.0, 0.0, 2.5], dir=[0.0, 0.0, -1.0], diffuse=[0.35] * 3,
                                  specular=[0.0] * 3, castshadow=False, type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
        return world

    @staticmethod
    def _rooms(world: mujoco.MjSpec, lay: dict[str, Any]) -> None:
        wb = world.worldbody
        floor = _material(world, "floor", lay["floor"], (0.8, 0.8), True)
        walls = _material(world, "walls", lay["walls"], (0.5, 0.5), True, specular=0.05)
        wb.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[ROOM_DEPTH, ROOM_HALF_Y, 0.05],
                    material=floor, friction=[1.0, 0.01, 0.001])
        h, t = ROOM_HEIGHT, WALL_THICKNESS / 2
        lo, hi = lay["y0"], lay["y0"] + lay["width"]
        # the dividing wall: two panels beside the doorway and a lintel above it (they collide)
        for name, y_from, y_to in (("wall_low", -ROOM_HALF_Y, lo), ("wall_high", hi, ROOM_HALF_Y)):
            wb.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0.0, (y_from + y_to) / 2, h / 2],
                        size=[t, (y_to - y_from) / 2, h / 2], material=walls)
        wb.add_geom(name="lintel", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0.0, (lo + hi) / 2, (h + DOOR_HEIGHT) / 2],
                    size=[t, (hi - lo) / 2, (h - DOOR_HEIGHT) / 2], material=walls)
        # the rooms' outer walls (visual only)
        for name, pos, size in (("wall_px", [ROOM_DEPTH + 0.02, 0.0, h / 2], [0.02, ROOM_HALF_Y, h / 2]),
                                ("wall_nx", [-ROOM_DEPTH - 0.02, 0.0, h / 2], [0.02, ROOM_HALF_Y, h / 2]),
                                ("wall_py", [0.0, ROOM_HALF_Y + 0.02, h / 2], [ROOM_DEPTH, 0.02, h / 2]),
                                ("wall_ny", [0.0, -ROOM_HALF_Y - 0.02, h / 2], [ROOM_DEPTH, 0.02, h / 2])):
            wb.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=pos, size=size, material=walls,
                        contype=0, conaffinity=0)

    @staticmethod
    def _door(world: mujoco.MjSpec, lay: dict[str, Any], door: dict[str, Any]) -> None:
        leaf_mat = _material(world, "door_leaf", lay["leaf"], (1.0, 1.0), True, specular=0.2)
        sy, sx = door["leaf_dir"], door["swing_side"]
        frame = world.worldbody.add_body(name=DOOR_NAME, pos=door["hinge"])
        # the frame's trim around the doorway (visual)
        lo, hi = door["doorway_y"]
        hy = door["hinge"][1]
        trim = [0.6, 0.58, 0.55, 1.0]
        for y in (lo, hi):
            frame.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0.0, y - hy, DOOR_HEIGHT / 2],
                           size=[WALL_THICKNESS / 2 + 0.01, 0.03, DOOR_HEIGHT / 2], rgba=trim, contype=0,
                           conaffinity=0, group=2)
        leaf = frame.add_body(name=f"{DOOR_NAME}/leaf")
        leaf.add_joint(name=HINGE_JOINT, type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0.0, 0.0, float(-sx * sy)],
                       range=[0.0, DOOR_RANGE], damping=lay["damping"], frictionloss=lay["frictionloss"],
                       armature=0.1)
        world.add_exclude(bodyname1="world", bodyname2=f"{DOOR_NAME}/leaf")  # the leaf turns inside the wall
        w = door["leaf_width"]
        leaf.add_geom(name=f"{DOOR_NAME}/leaf_panel", type=mujoco.mjtGeom.mjGEOM_BOX,
                      pos=[0.0, sy * w / 2, (DOOR_HEIGHT - 0.02) / 2 + 0.01],
                      size=[LEAF_THICKNESS / 2, w / 2 - 0.005, (DOOR_HEIGHT - 0.02) / 2], material=leaf_mat,
                      mass=15.0)
        y_handle = sy * door["handle_radius"]
        for name, side in (("handle_pos", 1.0), ("handle_neg", -1.0)):
            handle = leaf.add_body(name=f"{DOOR_NAME}/{name}", pos=[side * door["handle_offset"], y_handle,
                                                                    door["handle_z"]])
            handle.add_geom(name=f"{DOOR_NAME}/{name}_bar", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                            size=[HANDLE_RADIUS, HANDLE_HALF_LEN, 0.0], rgba=list(lay["handle_rgba"]),
                            contype=0, conaffinity=0, group=2, mass=0.0)
            handle.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[HANDLE_RADIUS, HANDLE_HALF_LEN, 0.0],
                            group=3, mass=0.2, friction=[1.5, 0.01, 0.001])
            for z in (-HANDLE_HALF_LEN + 0.01, HANDLE_HALF_LEN - 0.01):  # standoffs to the leaf
                handle.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, pos=[-side * HANDLE_OFF / 2, 0.0, z],
                                size=[HANDLE_OFF / 2, 0.008, 0.008], rgba=list(lay["handle_rgba"]), group=2,
                                mass=0.05)


@hookimpl
def molmo_scene_datasets() -> list[SceneDataset]:
    return [DoorRooms()]
