"""Articulated objects for open/close tasks, as an asset library with per-joint handle grasps.

Two sources, both built with MjSpec at run time (no asset file is copied into this repository):

* the kitchen items of the installed ``gymnasium-robotics`` package (microwave, sliding-door
  cabinet, two-door hinged cabinet), loaded from the package path with absolute mesh and
  texture paths;
* drawer chests made of primitives (one drawer on a slide joint, a horizontal bar handle).

Every object's front faces its local ``-y`` axis and rests on the plane ``z = 0`` of its root
frame after :attr:`ArticulatedObject.root_z` (a few millimetres of clearance under the
kitchen cabinets keep their doors from rubbing on the support). Joints close at ``q = 0`` (MolmoSpaces'
convention); :attr:`JointInfo.open_q` is the other end of the range.

Grasps (``<uid>/<joint>`` in the grasp library) are TCP poses in the frame of the joint's
child body (the moving part): ``+z`` approaches the handle from the front (local ``+y``),
``+y`` is the finger axis, across the handle bar.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import mujoco
import numpy as np

from molmo_lerobot.assets.catalog import AssetLibraryType
from molmo_lerobot.assets.grasps import GraspLibrary
from molmo_lerobot.assets.libraries import ObjectTableLibrary
from molmo_lerobot.paths import package_asset_dir

ROBOT = "franka"  # the analytic handle grasps are sized for the Franka hand


@dataclass(frozen=True)
class JointInfo:
    """One articulated joint: its name inside the object, its moving body and its handle bar."""

    name: str
    kind: str  # "hinge" | "slide"
    body: str  # the joint's child body (grasp frame)
    open_q: float  # joint position when fully open (closed is 0)
    handle_pos: tuple[float, float, float]  # handle bar centre in the body frame
    handle_axis: str  # "z" (vertical bar) | "x" (horizontal bar)
    handle_half_length: float
    label: str  # what a person calls the moving part ("door", "left door", "drawer")


@dataclass(frozen=True)
class ArticulatedObject:
    """An articulated asset: UID, metadata and how to build it."""

    uid: str
    category: str
    description: str  # e.g. "microwave"; the instruction says "open the <description>"
    synset: str
    source: str  # "gymnasium_robotics:<item>" | "primitive"
    root_body: str
    root_z: float  # height of the root frame above the surface the object stands on
    size: tuple[float, float, float]  # bounding box (x, y, z) in the object frame
    joints: tuple[JointInfo, ...]
    front: float  # distance from the root frame to the front of the closed handles (local -y)
    back: float  # distance from the root frame to the back panel (local +y)
    rgba: tuple[float, float, float, float] = (0.5, 0.5, 0.5, 1.0)

    def joint(self, name: str) -> JointInfo:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(f"articulated object {self.uid!r} has no joint {name!r} "
                       f"(joints: {', '.join(j.name for j in self.joints)})")

    def metadata(self) -> dict:
        """The asset-library metadata document (MolmoSpaces' fields + ``joints``)."""
        words = self.description.split()
        return {
            "assetId": self.uid,
            "category": self.category,
            "description": self.description,
            "description_long": f"a {self.description} with {len(self.joints)} articulated "
                                f"part{'s' if len(self.joints) > 1 else ''} ({self.source})",
            "description_short": {"one_word": words[-1], "two_words": " ".join(words[-2:]),
                                  "three_words": " ".join(words[-3:])},
            "synset": self.synset,
            "mass": None,
            "boundingBox": {"x": self.size[0], "y": self.size[1], "z": self.size[2]},
            "articulated": True,
            "root_z": self.root_z,
            "joints": {j.name: {"type": j.kind, "body": j.body, "closed": 0.0, "open": j.open_q, "label": j.label,
                                "handle_pos": list(j.handle_pos), "handle_axis": j.handle_axis}
                       for j in self.joints},
        }

    def spec(self) -> mujoco.MjSpec:
        """A fresh spec whose first top-level body is :attr:`root_body`."""
        if self.source.startswith("gymnasium_robotics:"):
            return _kitchen_spec(self.source.split(":", 1)[1])
        return _drawer_chest_spec(self)

    def mjcf(self) -> str:
        return self.spec().to_xml()


# Kitchen items from gymnasium-robotics -----------------------------------------------------------


def kitchen_asset_dir() -> Path:
    """``kitchen_assets`` inside the installed gymnasium-robotics package."""
    return package_asset_dir("gymnasium_robotics", "envs", "assets", "kitchen_franka", "kitchen_assets",
                             marker="item_assets", what="the kitchen articulated objects")


@cache
def _kitchen_xml(item: str) -> str:
    root = kitchen_asset_dir() / "item_assets"
    for part in ("asset", "chain"):
        if not (root / f"{item}_{part}.xml").is_file():
            raise FileNotFoundError(f"kitchen item {item!r}: {root / f'{item}_{part}.xml'} missing")
    return (f'<mujoco model="{item}"><compiler angle="radian"/>'
            f'<include file="{root / f"{item}_asset.xml"}"/>'
            f'<worldbody><include file="{root / f"{item}_chain.xml"}"/></worldbody></mujoco>')


def _kitchen_spec(item: str) -> mujoco.MjSpec:
    spec = mujoco.MjSpec.from_string(_kitchen_xml(item))
    root = kitchen_asset_dir()
    for mesh in spec.meshes:  # relative to the kitchen model's directories: make them absolute
        mesh.file = str(root / "meshes" / Path(mesh.file).name)
    for tex in spec.textures:
        if tex.file:
            tex.file = str(root / "textures" / Path(tex.file).name)
    spec.meshdir = spec.texturedir = ""
    return spec


# Drawer chests of primitives ---------------------------------------------------------------------

#: a chest's half extents, wall thickness and drawer travel (metres)
_CHEST_HALF, _CHEST_WALL, _CHEST_TRAVEL = (0.2, 0.18, 0.17), 0.012, 0.26


def _drawer_chest_spec(obj: ArticulatedObject) -> mujoco.MjSpec:
    hx, hy, hz = _CHEST_HALF
    t = _CHEST_WALL
    spec = mujoco.MjSpec()
    spec.modelname = obj.uid
    box = mujoco.mjtGeom.mjGEOM_BOX
    body = spec.worldbody.add_body(name=obj.root_body)
    rgba = list(obj.rgba)
    for name, size, pos in (("top", (hx, hy, t), (0.0, 0.0, hz - t)), ("bottom", (hx, hy, t), (0.0, 0.0, -hz + t)),
                            ("left", (t, hy, hz), (-hx + t, 0.0, 0.0)), ("right", (t, hy, hz), (hx - t, 0.0, 0.0)),
                            ("back", (hx, t, hz), (0.0, hy - t, 0.0))):
        body.add_geom(name=f"carcass_{name}", type=box, size=list(size), pos=list(pos), rgba=rgba)
    drawer = body.add_body(name="drawer", pos=[0.0, 0.0, 0.0])
    joint = obj.joints[0]
    drawer.add_joint(name=joint.name, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0.0, -1.0, 0.0],
                     range=[0.0, joint.open_q], damping=8.0, frictionloss=1.0, armature=0.01)
    dx, dz = hx - 2 * t - 0.003, hz - 2 * t - 0.003
    dy = hy - t - 0.01
    front_rgba = [min(1.0, c * 1.15) for c in rgba[:3]] + [1.0]
    for name, size, pos in (("front", (hx - 2 * t - 0.002, t, hz - 2 * t - 0.002), (0.0, -hy + t, 0.0)),
                            ("floor", (dx, dy, 0.005), (0.0, 0.0, -dz + 0.005)),
                            ("side_l", (0.005, dy, dz * 0.6), (-dx + 0.005, 0.0, -dz * 0.4)),
                            ("side_r", (0.005, dy, dz * 0.6), (dx - 0.005, 0.0, -dz * 0.4)),
                            ("rear", (dx, 0.005, dz * 0.6), (0.0, dy - 0.005, -dz * 0.4))):
        drawer.add_geom(name=f"drawer_{name}", type=box, size=list(size), pos=list(pos),
                        rgba=front_rgba if name == "front" else rgba, mass=0.3 if name == "front" else 0.1)
    hp = joint.handle_pos
    metal = [0.75, 0.75, 0.78, 1.0]
    drawer.add_geom(name="handle", type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.011, joint.handle_half_length, 0],
                    pos=list(hp), quat=[math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0], rgba=metal, mass=0.05,
                    friction=[1.0, 0.01, 0.001])
    standoff = -hy - hp[1]  # from the drawer front to the bar
    for sx in (-1, 1):
        drawer.add_geom(name=f"handle_post{'lr'[sx > 0]}", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                        size=[0.007, standoff / 2, 0],
                        pos=[sx * (joint.handle_half_length - 0.01), -hy - standoff / 2, hp[2]],
                        quat=[math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0], rgba=metal, mass=0.01)
    return spec


def _chest(uid: str, color: str, rgba: tuple[float, float, float, float]) -> ArticulatedObject:
    hx, hy, hz = _CHEST_HALF
    handle = JointInfo(name="drawer_slide", kind="slide", body="drawer", open_q=_CHEST_TRAVEL,
                       handle_pos=(0.0, -hy - 0.045, 0.0), handle_axis="x", handle_half_length=0.07,
                       label="drawer")
    return ArticulatedObject(uid=uid, category="drawer_chest", description=f"{color} drawer", synset="chest.n.02",
                             source="primitive", root_body=uid, root_z=hz, size=(2 * hx, 2 * hy, 2 * hz),
                             joints=(handle,), front=hy + 0.056, back=hy, rgba=rgba)


ARTICULATED_OBJECTS: dict[str, ArticulatedObject] = {
    o.uid: o for o in (
        ArticulatedObject(
            uid="kitchen_microwave", category="microwave", description="microwave", synset="microwave.n.02",
            source="gymnasium_robotics:microwave", root_body="microroot", root_z=0.0, size=(0.69, 0.44, 0.374),
            joints=(JointInfo("microwave", "hinge", "microdoorroot", -2.094, (0.475, -0.108, 0.0), "z", 0.13,
                              "door"),), front=0.304, back=0.22),
        ArticulatedObject(
            uid="kitchen_slide_cabinet", category="cabinet", description="sliding cabinet",
            synset="cabinet.n.01", source="gymnasium_robotics:slidecabinet", root_body="slide", root_z=0.203,
            size=(0.9, 0.6, 0.4),
            joints=(JointInfo("slide_cabinet", "slide", "slidelink", 0.44, (-0.183, -0.123, 0.0), "z", 0.159,
                              "sliding door"),), front=0.465, back=0.3),
        ArticulatedObject(
            uid="kitchen_hinge_cabinet", category="cabinet", description="cabinet", synset="cabinet.n.01",
            source="gymnasium_robotics:hingecabinet", root_body="hingecab", root_z=0.205, size=(0.8, 0.6, 0.4),
            joints=(JointInfo("left_hinge_cabinet", "hinge", "hingeleftdoor", -1.57, (0.302, -0.128, 0.0), "z", 0.16,
                              "left door"),
                    JointInfo("right_hinge_cabinet", "hinge", "hingerightdoor", 1.57, (-0.302, -0.128, 0.0), "z",
                              0.16, "right door")), front=0.47, back=0.3),
        _chest("drawer_chest_white", "white", (0.88, 0.87, 0.82, 1.0)),
        _chest("drawer_chest_wood", "wooden", (0.55, 0.38, 0.22, 1.0)),
        _chest("drawer_chest_green", "green", (0.3, 0.5, 0.35, 1.0)),
    )
}

#: half the open Franka gripper span (fingers included) and how far along the bar grasps are spread
_GRASP_SPREAD = 0.04


def handle_grasps(obj: ArticulatedObject, joint: str) -> np.ndarray:
    """Grasp poses ``(N, 4, 4)`` on ``joint``'s handle, in the joint's child body frame (module docstring)."""
    info = obj.joint(joint)
    approach = np.array([0.0, 1.0, 0.0])
    along = np.array([0.0, 0.0, 1.0]) if info.handle_axis == "z" else np.array([1.0, 0.0, 0.0])
    across = np.cross(along, approach)  # horizontal bar: vertical fingers; vertical bar: horizontal fingers
    out = []
    for t in (0.0, -_GRASP_SPREAD, _GRASP_SPREAD):
        if abs(t) > info.handle_half_length - 0.035:
            continue
        for sign in (1.0, -1.0):
            y = sign * across
            T = np.eye(4)
            T[:3, 0], T[:3, 1], T[:3, 2] = np.cross(y, approach), y, approach
            T[:3, 3] = np.asarray(info.handle_pos) + t * along
            out.append(T)
    return np.stack(out)


class ArticulatedGraspLibrary(GraspLibrary):
    """Per-joint handle grasps: NPZ files under ``root`` if present, else :func:`handle_grasps`."""

    def __init__(self, root: str | Path | None = None) -> None:
        from molmo_lerobot.assets.grasps import builtin_grasp_dir

        super().__init__(root or builtin_grasp_dir().parent / "articulated", name="articulated")

    def _analytic(self, uid: str, robot: str, joint: str | None) -> bool:
        obj = ARTICULATED_OBJECTS.get(uid)
        return obj is not None and robot == ROBOT and joint is not None and any(j.name == joint for j in obj.joints)

    def joints(self, uid: str, robot: str = "franka") -> list[str]:
        found = super().joints(uid, robot)
        if found or uid not in ARTICULATED_OBJECTS or robot != ROBOT:
            return found
        return sorted(j.name for j in ARTICULATED_OBJECTS[uid].joints)

    def has(self, uid: str, robot: str = "franka", joint: str | None = None) -> bool:
        return super().has(uid, robot, joint) or self._analytic(uid, robot, joint)

    def load(self, uid: str, robot: str = "franka", joint: str | None = None) -> np.ndarray | None:
        got = super().load(uid, robot, joint)
        if got is None and joint is not None and self._analytic(uid, robot, joint):
            return handle_grasps(ARTICULATED_OBJECTS[uid], joint)
        return got

    def count(self, uid: str, robot: str = "franka", joint: str | None = None) -> int | None:
        got = super().count(uid, robot, joint)
        if got is None and self._analytic(uid, robot, joint):
            grasps = self.load(uid, robot, joint)
            return None if grasps is None else len(grasps)
        return got


class ArticulatedAssetLibrary(ObjectTableLibrary):
    """The articulated objects above as an asset library (name ``articulated``)."""

    def __init__(self) -> None:
        super().__init__("articulated", ARTICULATED_OBJECTS, ArticulatedGraspLibrary())


#: The articulated objects as a library type (the ``articulated`` plugin provides it).
ARTICULATED_LIBRARY_TYPE = AssetLibraryType("articulated", lambda settings, catalog: [ArticulatedAssetLibrary()],
                                            priority=200)
