"""LIBERO's articulated fixtures in the textured rooms (``libero_fixture_rooms``), a scene plugin.

House ``i`` is house ``i`` of ``libero_rooms`` (:mod:`molmo_lerobot.content.libero.rooms`: the same room, table,
decor and lights) with its loose objects replaced: one fixture of the ``libero_fixtures`` library
(:mod:`molmo_lerobot.content.libero.fixtures`) stands on the table facing the robot, its closed handles
:data:`FRONT` ahead of the base (an open drawer's handle then still lies where franka_droid reaches
it with a level hand), and two of the house's own graspable objects stand at the table's sides as
distractors, clear of the drawers' travel. Choices come from a random stream seeded by ``i`` alone.

Body names: the fixture is the body named by its UID, its parts and joints prefixed ``"<uid>/"``
(joint ``libero_white_cabinet/top_level``); the distractors are free bodies named by their UIDs.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.assets.catalog import AssetLibraryType
from molmo_lerobot.content.libero.fixtures import FIXTURE_LIBRARY_TYPE, LIBERO_FIXTURES, LiberoFixture
from molmo_lerobot.content.libero.rooms import TABLE_NEAR, LiberoRooms, referring_expression
from molmo_lerobot.sim.scenes import SceneDataset

_SALT = 0xF1C57
#: distance range from the robot base to the front of the closed handles (m)
FRONT = (0.72, 0.78)
#: sideways offset range of the fixture's centre (m)
OFFSET_Y = (-0.06, 0.06)
#: yaw turning a fixture's local -y front towards the robot (world -x)
FACING_QUAT = (math.cos(-math.pi / 4), 0.0, 0.0, math.sin(-math.pi / 4))
#: free space between the fixture's sides and a distractor's centre (an open drawer and the arm beside it fit in it)
SIDE_CLEARANCE = 0.3
N_DISTRACTORS = 2
FIXTURES = tuple(sorted(LIBERO_FIXTURES))


@cache
def _fixture_layout(house_index: int) -> dict[str, Any]:
    """The fixture, its pose and the distractors' poses of a house, drawn in a fixed order."""
    room = LiberoRooms().metadata(house_index)
    height, half_y = room["table_height"], room["table_extent"]["y"][1]
    graspable = [o for o in LiberoRooms().objects(house_index) if o.graspable]
    rng = np.random.default_rng([_SALT, house_index])
    fixture = LIBERO_FIXTURES[FIXTURES[int(rng.integers(len(FIXTURES)))]]
    front = float(rng.uniform(*FRONT))
    y0 = float(rng.uniform(*OFFSET_Y))
    x = front + fixture.front
    pose = [round(x, 5), round(y0, 5), round(height + fixture.root_z, 5), *FACING_QUAT]
    distractors = []
    for k, side in zip(rng.choice(len(graspable), N_DISTRACTORS, replace=False), (1.0, -1.0), strict=True):
        obj = graspable[int(k)]
        r = math.hypot(*obj.half_extents[:2])
        lo = fixture.size[0] / 2 + SIDE_CLEARANCE
        hi = max(lo, half_y - 0.05 - r)
        y = y0 + side * float(rng.uniform(lo, hi))
        y = max(-half_y + 0.05 + r, min(half_y - 0.05 - r, y))
        dx = float(rng.uniform(TABLE_NEAR + 0.08 + r, TABLE_NEAR + 0.4))
        yaw = float(rng.uniform(-math.pi, math.pi))
        distractors.append((obj, [round(dx, 5), round(y, 5), round(height + obj.half_extents[2] + 0.001, 5),
                                  round(math.cos(yaw / 2), 5), 0.0, 0.0, round(math.sin(yaw / 2), 5)]))
    return {"fixture": fixture, "pose": pose, "distractors": distractors}


def _attach_fixture(world: mujoco.MjSpec, fixture: LiberoFixture, pose: list[float]) -> None:
    frame = world.worldbody.add_frame(pos=list(pose[:3]), quat=list(pose[3:]))
    child = fixture.spec()
    frame.attach_body(child.body(fixture.root_body), f"{fixture.uid}/", "")
    world.body(f"{fixture.uid}/{fixture.root_body}").name = fixture.uid


class LiberoFixtureRooms(LiberoRooms):
    """A LIBERO fixture on the table of a textured LIBERO room, two distractors (module docstring)."""

    name = "libero_fixture_rooms"
    aliases = ()

    def fixture(self, house_index: int) -> LiberoFixture:
        self.check_house(house_index)
        return _fixture_layout(house_index)["fixture"]

    def metadata(self, house_index: int) -> dict[str, Any]:
        meta = super().metadata(house_index)
        lay = _fixture_layout(house_index)
        fx = lay["fixture"]
        distractors = [obj for obj, _ in lay["distractors"]]
        objects: dict[str, Any] = {fx.uid: {
            "asset_id": fx.uid, "category": fx.category, "name": fx.name, "color": fx.color,
            "material": fx.material, "description": fx.description, "referring_expression": f"the {fx.description}",
            "articulated": True, "default_pose": lay["pose"],
            "joints": {j.name: {"joint": f"{fx.uid}/{j.name}", "body": f"{fx.uid}/{j.body}", "type": j.kind,
                                "closed": 0.0, "open": j.open_q, "label": j.label} for j in fx.joints},
        }}
        for obj, pose in lay["distractors"]:
            objects[obj.uid] = {"asset_id": obj.uid, "category": obj.category, "name": obj.name, "color": obj.color,
                                "material": obj.material, "description": obj.description,
                                "referring_expression": referring_expression(obj, distractors),
                                "default_pose": pose, "articulated": False, "receptacle": obj.receptacle,
                                "graspable": obj.graspable}
        meta["scene_dataset"] = self.name
        meta["objects"] = objects
        meta.pop("placement_region", None)
        return meta

    def build(self, house_index: int) -> mujoco.MjSpec:
        world = super().build(house_index)
        world.modelname = f"{self.name}_{house_index}"
        lay = _fixture_layout(house_index)
        kept = {obj.uid: pose for obj, pose in lay["distractors"]}
        for obj in self.objects(house_index):  # the room's loose objects: all but the distractors go
            body = world.body(obj.uid)
            if obj.uid in kept:  # the frame the room attached it with takes it where this house puts it
                body.frame.pos, body.frame.quat = kept[obj.uid][:3], kept[obj.uid][3:]
            else:
                world.delete(body)
        _attach_fixture(world, lay["fixture"], lay["pose"])
        return world


@hookimpl
def molmo_scene_datasets() -> list[SceneDataset]:
    return [LiberoFixtureRooms()]


@hookimpl
def molmo_asset_libraries() -> list[AssetLibraryType]:
    return [FIXTURE_LIBRARY_TYPE]
