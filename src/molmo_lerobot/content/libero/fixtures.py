"""LIBERO's articulated fixtures (cabinets with drawers) as an asset library (``libero_fixtures``).

The fixtures are read in place from ``articulated_objects/`` of the installed LIBERO asset
distributions with :class:`mujoco.MjSpec` and normalised to the conventions of
:mod:`molmo_lerobot.content.articulated.objects`:

* every joint closes at ``q = 0``: its range becomes ``[0, open]`` (LIBERO's drawers run a centimetre
  past closed, ``[-0.16, 0.01]``; that centimetre is cut);
* the front faces the root's local ``-y`` (checked: every slide opens towards ``-y``, every handle
  is the front-most part of its moving body), the root frame stands on the plane ``z = 0``
  (:attr:`LiberoFixture.root_z` lifts it there);
* collision geoms go to group 3 (never drawn by a camera), with MuJoCo's default contact
  parameters (LIBERO's ``solref 0.001`` is far below what a 2 ms step resolves); a body
  without an inertial takes its mass from its collision geoms only (visual meshes weigh nothing);
* mesh and texture files are absolute paths into the package (textures downscaled as
  :func:`~molmo_lerobot.content.libero.objects.texture_file` does).

Each joint's handle is found from the geometry: the collision geom of the joint's moving body
reaching farthest to the front (ties within :data:`_FRONT_TIE` broken by length across the
front), its bar along the longer of its horizontal (``x``) and vertical (``z``) extents. Handle
grasps (``<uid>/<joint>`` in the grasp library) are TCP poses in the moving body's frame: ``+z``
approaches the bar from the front (local ``+y``), ``+y`` is the finger axis across the bar, at
the bar's centre and :data:`GRASP_SPREAD` to either side where the bar is long enough, both
finger orientations; a horizontal bar within :data:`LOW_HANDLE` of the support is approached from
above its front instead (:data:`PITCHES`), since the lower finger of a level grasp would hit the
support. The same poses serve ``franka`` and ``franka_droid`` (MolmoSpaces' unified TCP
convention). The metadata records each fixture's licence from the distribution that ships its
MJCF (:func:`~molmo_lerobot.content.libero.objects.license_of`).

Not included: the stoves and faucets (knobs and levers are turned, not opened); the microwave
(it loads and normalises, but the scripted expert opened it in 1 of 17 tries: its grip on the
small door handle slips after at most 0.2 rad, so an open_v2 episode of it would measure the
expert); the window, sliding cabinet
and short fridge (their MJCF needs more than normalising: zero-mass moving bodies with mesh
collision, a non-MJCF ``<region>`` element).
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
from molmo_lerobot.assets.libraries import AssetError, ObjectTableLibrary
from molmo_lerobot.content.libero.objects import COLLISION_GROUP, PACKAGE, assets_root, license_of, texture_file
from molmo_lerobot.paths import home_dir

#: robots whose grasp poses these are (one TCP convention)
ROBOTS = ("franka", "franka_droid")
#: how far along the bar the off-centre grasps sit, and the bar length they need beyond it
GRASP_SPREAD = 0.012
_SPREAD_MARGIN = 0.03
#: a horizontal bar lower than this above the fixture's support (m) leaves no room under it for a finger of
#: the open gripper (half its span and the finger): it is approached from above its front, these pitches (rad)
LOW_HANDLE = 0.06
PITCHES = (math.radians(55.0),)
#: geoms whose front is within this of the front-most one compete for being the handle
_FRONT_TIE = 0.004


@dataclass(frozen=True)
class FixtureJoint:
    """One joint of a fixture as LIBERO names it, and what a person calls its moving part."""

    name: str
    label: str  # "top drawer", "door"


@dataclass(frozen=True)
class JointInfo:
    """A normalised joint (see :class:`molmo_lerobot.content.articulated.objects.JointInfo`): name, kind, child body,
    open end, handle bar (centre in the body frame, axis ``x``/``z``, half length), label."""

    name: str
    kind: str
    body: str
    open_q: float
    handle_pos: tuple[float, float, float]
    handle_axis: str
    handle_half_length: float
    label: str


@dataclass(frozen=True)
class LiberoFixture:
    """A LIBERO articulated fixture: its MJCF under ``articulated_objects/`` and what the file does not say."""

    uid: str
    file: str  # MJCF file name under articulated_objects/
    category: str
    name: str  # "cabinet"
    color: str
    material: str
    synset: str
    joint_labels: tuple[FixtureJoint, ...]

    @property
    def xml_path(self) -> Path:
        return assets_root() / "articulated_objects" / self.file

    @property
    def description(self) -> str:
        """``"<colour> <name>"`` ("white cabinet")."""
        return f"{self.color} {self.name}".strip()

    @property
    def root_body(self) -> str:
        return self.uid

    def spec(self) -> mujoco.MjSpec:
        """A fresh normalised spec (module docstring) whose first top-level body is named :attr:`uid`."""
        return _normalised_spec(self)

    def mjcf(self) -> str:
        return self.spec().to_xml()

    @property
    def joints(self) -> tuple[JointInfo, ...]:
        return _geometry(self.uid)["joints"]

    @property
    def root_z(self) -> float:
        return _geometry(self.uid)["root_z"]

    @property
    def size(self) -> tuple[float, float, float]:
        return _geometry(self.uid)["size"]

    @property
    def front(self) -> float:
        """Distance from the root frame to the front of the closed handles (local ``-y``)."""
        return _geometry(self.uid)["front"]

    @property
    def back(self) -> float:
        return _geometry(self.uid)["back"]

    def joint(self, name: str) -> JointInfo:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(f"libero fixture {self.uid!r} has no joint {name!r} "
                       f"(joints: {', '.join(j.name for j in self.joints)})")

    def metadata(self) -> dict:
        """The asset-library metadata document (MolmoSpaces' fields, ``joints``, source and licence)."""
        words = self.description.split()
        sx, sy, sz = self.size
        return {
            "assetId": self.uid,
            "category": self.category,
            "description": self.description,
            "description_long": f"a {self.color} {self.material} {self.name} with "
                                f"{', '.join(j.label for j in self.joints)} "
                                f"({sx * 100:.0f} x {sy * 100:.0f} x {sz * 100:.0f} cm)",
            "description_short": {"one_word": words[-1], "two_words": " ".join(words[-2:]),
                                  "three_words": " ".join(words[-3:])},
            "synset": self.synset,
            "mass": None,
            "boundingBox": {"x": sx, "y": sy, "z": sz},
            "color": self.color,
            "material": self.material,
            "articulated": True,
            "root_z": self.root_z,
            "joints": {j.name: {"type": j.kind, "body": j.body, "closed": 0.0, "open": j.open_q, "label": j.label,
                                "handle_pos": list(j.handle_pos), "handle_axis": j.handle_axis}
                       for j in self.joints},
            "source": f"{PACKAGE}/assets/articulated_objects/{self.file}",
            "license": license_of(self.xml_path),
        }


def _drawers(*names: str) -> tuple[FixtureJoint, ...]:
    return tuple(FixtureJoint(f"{level}_level", f"{level} drawer") for level in names)


LIBERO_FIXTURES: dict[str, LiberoFixture] = {f.uid: f for f in (
    LiberoFixture("libero_white_cabinet", "white_cabinet.xml", "cabinet", "cabinet", "white", "wooden",
                  "cabinet.n.01", _drawers("top", "middle", "bottom")),
    LiberoFixture("libero_wooden_cabinet", "wooden_cabinet.xml", "cabinet", "cabinet", "dark wooden", "wooden",
                  "cabinet.n.01", _drawers("top", "middle", "bottom")),
    LiberoFixture("libero_yellow_cabinet", "yellow_cabinet.xml", "cabinet", "cabinet", "yellow", "wooden",
                  "cabinet.n.01", _drawers("top", "middle", "bottom")),
)}


# Normalising ------------------------------------------------------------------------------------


def _normalised_spec(fx: LiberoFixture) -> mujoco.MjSpec:
    path = fx.xml_path
    if not path.is_file():
        raise AssetError(f"libero fixture {fx.uid!r}: {path} missing")
    spec = mujoco.MjSpec.from_file(str(path))
    spec.modelname = fx.uid
    base = path.parent
    for mesh in spec.meshes:
        mesh.file = str(base / spec.meshdir / mesh.file)
    for tex in spec.textures:
        if tex.file:
            tex.file = str(texture_file(base / spec.texturedir / tex.file))
    spec.meshdir = spec.texturedir = ""
    spec.compiler.inertiagrouprange = [COLLISION_GROUP, COLLISION_GROUP]
    default = mujoco.MjSpec().default.geom
    for geom in spec.geoms:
        if geom.contype or geom.conaffinity:
            geom.group = COLLISION_GROUP
            geom.contype = geom.conaffinity = 1
            geom.solref, geom.solimp = default.solref, default.solimp
    for site in spec.sites:
        site.group = COLLISION_GROUP  # LIBERO's region markers: never drawn
    known = {j.name for j in fx.joint_labels}
    for joint in spec.joints:
        if joint.name not in known:
            raise AssetError(f"{path}: joint {joint.name!r} has no label in libero_fixtures")
        lo, hi = joint.range
        open_q = lo if abs(lo) >= abs(hi) else hi
        joint.range = [min(0.0, open_q), max(0.0, open_q)]
    spec.worldbody.first_body().name = fx.uid
    return spec


def _aabb(model: mujoco.MjModel, data: mujoco.MjData, geoms: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """World bounding box of ``geoms``."""
    corners = []
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    for g in geoms:
        centre, half = model.geom_aabb[g][:3], model.geom_aabb[g][3:]
        local = centre + signs * half
        corners.append(data.geom_xpos[g] + local @ data.geom_xmat[g].reshape(3, 3).T)
    pts = np.concatenate(corners)
    return pts.min(0), pts.max(0)


@cache
def _geometry(uid: str) -> dict:
    """Joints with their handles, resting height, size, front and back of a fixture (compiled once, closed)."""
    fx = LIBERO_FIXTURES[uid]
    model = fx.spec().compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    collision = [g for g in range(model.ngeom) if model.geom_group[g] == COLLISION_GROUP]
    lo, hi = _aabb(model, data, collision)
    root = model.body(uid).id
    if np.abs(data.xpos[root]).max() > 1e-9 or np.abs(data.xmat[root] - np.eye(3).ravel()).max() > 1e-9:
        raise AssetError(f"{fx.xml_path}: the top body is not at the origin")
    joints = []
    for label in fx.joint_labels:
        jid = model.joint(label.name).id
        body = int(model.jnt_bodyid[jid])
        kind = {int(mujoco.mjtJoint.mjJNT_HINGE): "hinge", int(mujoco.mjtJoint.mjJNT_SLIDE): "slide"}.get(
            int(model.jnt_type[jid]))
        if kind is None:
            raise AssetError(f"{fx.xml_path}: joint {label.name!r} is neither hinge nor slide")
        lo_q, hi_q = model.jnt_range[jid]
        open_q = float(lo_q if abs(lo_q) > abs(hi_q) else hi_q)
        mine = [g for g in collision if model.geom_bodyid[g] == body]
        boxes = {g: _aabb(model, data, [g]) for g in mine}
        front = min(b[0][1] for b in boxes.values())
        ties = [g for g in mine if boxes[g][0][1] <= front + _FRONT_TIE]
        handle = max(ties, key=lambda g: max(boxes[g][1][0] - boxes[g][0][0], boxes[g][1][2] - boxes[g][0][2]))
        hlo, hhi = boxes[handle]
        axis = "x" if hhi[0] - hlo[0] >= hhi[2] - hlo[2] else "z"
        half = float((hhi - hlo)[0 if axis == "x" else 2] / 2)
        centre_world = (hlo + hhi) / 2
        if kind == "slide":
            direction = data.xmat[body].reshape(3, 3) @ model.jnt_axis[jid] * np.sign(open_q)
            if direction[1] > -0.99:
                raise AssetError(f"{fx.xml_path}: joint {label.name!r} does not open towards the front (-y)")
        centre = data.xmat[body].reshape(3, 3).T @ (centre_world - data.xpos[body])
        cx, cy, cz = (round(float(v), 6) for v in centre)
        joints.append(JointInfo(label.name, kind, model.body(body).name, open_q, (cx, cy, cz), axis, round(half, 6),
                                label.label))
    handle_front = min(float(data.xpos[model.body(j.body).id][1] + data.xmat[model.body(j.body).id].reshape(3, 3)[1]
                             @ np.asarray(j.handle_pos)) for j in joints)
    return {"joints": tuple(joints), "root_z": round(float(-lo[2]), 6),
            "size": tuple(round(float(v), 6) for v in hi - lo), "front": round(-min(lo[1], handle_front), 6),
            "back": round(float(hi[1]), 6)}


# Grasps -----------------------------------------------------------------------------------------


def handle_grasps(fx: LiberoFixture, joint: str) -> np.ndarray:
    """Grasp poses ``(N, 4, 4)`` on ``joint``'s handle, in the joint's moving body frame (module docstring)."""
    info = fx.joint(joint)
    along = np.array([0.0, 0.0, 1.0]) if info.handle_axis == "z" else np.array([1.0, 0.0, 0.0])
    # level, fingers straddling the bar; a horizontal bar too low for the lower finger is approached from
    # above its front instead
    low = info.handle_axis == "x" and info.handle_pos[2] + fx.root_z < LOW_HANDLE
    pitches = PITCHES if low else (0.0,)
    out = []
    for pitch in pitches:
        approach = np.array([0.0, math.cos(pitch), -math.sin(pitch)])
        across = np.cross(along, approach)
        for t in (0.0, -GRASP_SPREAD, GRASP_SPREAD):
            if t and info.handle_half_length < GRASP_SPREAD + _SPREAD_MARGIN:
                continue
            for sign in (1.0, -1.0):
                y = sign * across
                T = np.eye(4)
                T[:3, 0], T[:3, 1], T[:3, 2] = np.cross(y, approach), y, approach
                T[:3, 3] = np.asarray(info.handle_pos) + t * along
                out.append(T)
    return np.stack(out)


class FixtureGraspLibrary(GraspLibrary):
    """Per-joint handle grasps of the fixtures, computed from their geometry (module docstring)."""

    def __init__(self) -> None:
        super().__init__(home_dir() / "grasps" / "libero_fixtures", name="libero_fixtures")

    def _analytic(self, uid: str, robot: str, joint: str | None) -> bool:
        fx = LIBERO_FIXTURES.get(uid)
        return fx is not None and robot in ROBOTS and joint is not None and any(j.name == joint for j in fx.joints)

    def joints(self, uid: str, robot: str = "franka") -> list[str]:
        if uid not in LIBERO_FIXTURES or robot not in ROBOTS:
            return super().joints(uid, robot)
        return sorted(j.name for j in LIBERO_FIXTURES[uid].joints)

    def has(self, uid: str, robot: str = "franka", joint: str | None = None) -> bool:
        return self._analytic(uid, robot, joint) or super().has(uid, robot, joint)

    def load(self, uid: str, robot: str = "franka", joint: str | None = None) -> np.ndarray | None:
        if joint is not None and self._analytic(uid, robot, joint):
            return handle_grasps(LIBERO_FIXTURES[uid], joint)
        return super().load(uid, robot, joint)

    def count(self, uid: str, robot: str = "franka", joint: str | None = None) -> int | None:
        if joint is not None and self._analytic(uid, robot, joint):
            return len(handle_grasps(LIBERO_FIXTURES[uid], joint))
        return super().count(uid, robot, joint)


class FixtureAssetLibrary(ObjectTableLibrary):
    """The fixtures above as an asset library (name ``libero_fixtures``)."""

    def __init__(self) -> None:
        super().__init__("libero_fixtures", LIBERO_FIXTURES, FixtureGraspLibrary())


#: The fixtures as a library type (the ``libero_fixture_rooms`` plugin provides it).
FIXTURE_LIBRARY_TYPE = AssetLibraryType("libero_fixtures", lambda settings, catalog: [FixtureAssetLibrary()],
                                        priority=140)
