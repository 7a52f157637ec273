"""Grasps of the ``libero`` objects, computed from their collision geometry and cached.

Antipodal sampling with a gripper collision check, for the grippers of :data:`GRIPPERS`
(``franka_droid``'s Robotiq 2F-85 and ``franka``'s Panda hand, their real collision geometry, open):

1. closing lines: finger axes in :data:`AZIMUTHS` horizontal directions of the resting object,
   lines on a :data:`LINE_SPACING` grid across its bounding box;
2. along each line the solid runs of the collision primitives (gaps a finger cannot enter merged),
   kept where the run is narrower than the gripper's ``max_width`` and both end faces are antipodal
   (normals within :data:`FRICTION_CONE_DEG` of the closing axis);
3. approach directions perpendicular to the finger axis, from straight down to horizontal
   (:data:`APPROACH_TILTS_DEG`), the TCP (the pads' pinch point) at the run's middle;
4. the object's surface points (:data:`SURFACE_SPACING` samples) must lie outside the box (in the
   TCP frame) around every collision geom of the open gripper, swept back along the approach, and
   outside the pads' closing sweep.

Candidates are ranked by distance from the centre of mass (lifting torque), then tilt from
straight down, and the best :data:`MAX_GRASPS` are kept, first the best. Everything is a fixed grid,
so the result is deterministic. Files are written on first use into the cache dir
(``$MOLMO_LEROBOT_HOME/grasps/libero-v<GENERATOR_VERSION>/<robot>/<uid>.npz``, the usual grasp-library
layout) and read from there afterwards.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import mujoco
import numpy as np

from molmo_lerobot.assets.grasps import GraspLibrary, save_grasp_file
from molmo_lerobot.paths import home_dir

GENERATOR_VERSION = 1
AZIMUTHS = 8
LINE_SPACING = 0.006
STEP = 0.0015
FRICTION_CONE_DEG = 20.0
APPROACH_TILTS_DEG = (0.0, 20.0, -20.0, 40.0, -40.0, 60.0, -60.0, 90.0, -90.0)
SURFACE_SPACING = 0.004
MAX_GRASPS = 96
#: gaps narrower than this along a closing line are bridged (no finger fits in)
MIN_FINGER_GAP = 0.02
#: clearance kept between the object's surface and the open gripper
HAND_CLEARANCE = 0.002
#: how far back along the approach the open gripper's path is checked (the pre-grasp distance and more)
APPROACH_SWEEP = 0.15


def grasp_dir() -> Path:
    return home_dir() / "grasps" / f"libero-v{GENERATOR_VERSION}"


def surface_points(prims, spacing: float = SURFACE_SPACING) -> np.ndarray:
    """Points on the outer surface of the union of ``prims`` (body frame)."""
    out = []
    for p in prims:
        if p.kind == "box":
            pts = []
            for axis in range(3):
                a, b = [k for k in range(3) if k != axis]
                ga = np.linspace(-p.size[a], p.size[a], max(2, int(2 * p.size[a] / spacing) + 1))
                gb = np.linspace(-p.size[b], p.size[b], max(2, int(2 * p.size[b] / spacing) + 1))
                A, B = np.meshgrid(ga, gb)
                for sign in (-1.0, 1.0):
                    q = np.zeros((A.size, 3))
                    q[:, a], q[:, b], q[:, axis] = A.ravel(), B.ravel(), sign * p.size[axis]
                    pts.append(q)
            local = np.concatenate(pts)
        else:
            r, h = p.size
            n_ring = max(8, int(2 * math.pi * r / spacing))
            ang = np.arange(n_ring) * 2 * math.pi / n_ring
            zs = np.linspace(-h, h, max(2, int(2 * h / spacing) + 1))
            A, Z = np.meshgrid(ang, zs)
            side = np.stack([r * np.cos(A.ravel()), r * np.sin(A.ravel()), Z.ravel()], axis=1)
            radii = np.linspace(0, r, max(2, int(r / spacing) + 1))
            R, A2 = np.meshgrid(radii, ang)
            disc = np.stack([R.ravel() * np.cos(A2.ravel()), R.ravel() * np.sin(A2.ravel())], axis=1)
            caps = [np.column_stack([disc, np.full(len(disc), s * h)]) for s in (-1.0, 1.0)]
            local = np.concatenate([side, *caps])
        out.append(p.pos + local @ p.rot.T)
    pts = np.concatenate(out)
    inside_other = np.zeros(len(pts), dtype=bool)
    start = 0
    for i, chunk in enumerate(out):
        sl = slice(start, start + len(chunk))
        for j, q in enumerate(prims):
            if i != j:
                inside_other[sl] |= q.contains(pts[sl], margin=-1e-4)
        start += len(chunk)
    return pts[~inside_other]


def _inside(prims, points: np.ndarray) -> np.ndarray:
    inside = np.zeros(points.shape[:-1], dtype=bool)
    for p in prims:
        inside |= p.contains(points)
    return inside


def _normal_at(prims, point: np.ndarray, into: np.ndarray) -> np.ndarray:
    """Outward normal where the line enters the solid at ``point`` going along ``into``."""
    probe = point + 0.0005 * into
    for p in prims:
        if p.contains(probe[None])[0]:
            return p.normal(point[None])[0]
    return -into


def _pose(approach: np.ndarray, finger: np.ndarray, pos: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = np.cross(finger, approach), finger, approach, pos
    return T


def _candidates(prims, max_width: float) -> list[tuple[float, np.ndarray, np.ndarray, np.ndarray]]:
    """(centre-of-grip, finger axis, horizontal across axis) of every antipodal closing run."""
    corners = np.concatenate([p.corners() for p in prims])
    lo, hi = corners.min(0), corners.max(0)
    reach = float(np.linalg.norm(hi - lo)) / 2 + 0.01
    ts = np.arange(-reach, reach + STEP / 2, STEP)
    cos_cone = math.cos(math.radians(FRICTION_CONE_DEG))
    out = []
    for k in range(AZIMUTHS):
        a = math.pi * k / AZIMUTHS
        y = np.array([math.cos(a), math.sin(a), 0.0])
        u = np.array([-math.sin(a), math.cos(a), 0.0])
        us = np.arange(-reach, reach + 1e-9, LINE_SPACING)
        hs = np.arange(lo[2] + LINE_SPACING / 2, hi[2], LINE_SPACING)
        U, H = np.meshgrid(us, hs, indexing="ij")
        origins = U.ravel()[:, None] * u + H.ravel()[:, None] * np.array([0.0, 0.0, 1.0])
        pts = origins[:, None, :] + ts[None, :, None] * y
        solid = _inside(prims, pts)
        for li in np.flatnonzero(solid.any(axis=1)):
            row = solid[li].astype(np.int8)
            edges = np.diff(np.concatenate([[0], row, [0]]))
            starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
            runs: list[list[int]] = []
            for s, e in zip(starts, ends, strict=True):
                if runs and (ts[s] - ts[runs[-1][1]]) < MIN_FINGER_GAP:
                    runs[-1][1] = e
                else:
                    runs.append([s, e])
            for s, e in runs:
                width = ts[e] - ts[s]
                if width > max_width or width < 0.004:
                    continue
                p0, p1 = origins[li] + ts[s] * y, origins[li] + ts[e] * y
                n0, n1 = _normal_at(prims, p0, y), _normal_at(prims, p1, -y)
                if n0 @ -y < cos_cone or n1 @ y < cos_cone:
                    continue
                out.append((float(width), (p0 + p1) / 2, y, u))
    return out


@dataclass(frozen=True)
class Gripper:
    """A robot's gripper as the grasp search sees it: ``build`` gives its root body (with everything
    below it) and the TCP site's name; ``open_qpos`` the joint positions that open it (joints not named
    stay at their reference); ``max_width`` the widest grip (m, the stroke less a margin); the pads'
    sweep while closing: half width (x), open position (|y|) and half length along the approach (m)."""

    build: Callable[[], tuple[mujoco.MjsBody, str]]
    max_width: float
    pad_half_width: float
    open_pad_y: float
    pad_half_length: float
    open_qpos: dict[str, float] = field(default_factory=dict)


def _droid_gripper() -> tuple[mujoco.MjsBody, str]:
    from molmo_lerobot.robots.franka_droid import load_droid_spec

    return load_droid_spec().body("gripper/base"), "gripper/grasp_site"


def _panda_hand() -> tuple[mujoco.MjsBody, str]:
    from molmo_lerobot.robots.franka import load_franka_spec

    return load_franka_spec().body("panda0_link7"), "tcp"  # the hand and fingers hang from link 7


#: robots whose grasps this library computes
GRIPPERS = {
    "franka_droid": Gripper(_droid_gripper, max_width=0.075, pad_half_width=0.011, open_pad_y=0.044,
                            pad_half_length=0.02),
    "franka": Gripper(_panda_hand, max_width=0.07, pad_half_width=0.01, open_pad_y=0.04, pad_half_length=0.02,
                      open_qpos={"finger_joint1": 0.04, "finger_joint2": 0.04}),
}


def gripper(robot: str) -> Gripper:
    if robot not in GRIPPERS:
        raise ValueError(f"libero grasps: no gripper model for robot {robot!r} (have {sorted(GRIPPERS)})")
    return GRIPPERS[robot]


@cache
def hand_boxes(robot: str) -> np.ndarray:
    """``(K, 2, 3)`` lower/upper corners of every collision geom of ``robot``'s open gripper, as boxes
    aligned with its TCP frame, each swept :data:`APPROACH_SWEEP` back along the approach (the way in)."""
    hand = gripper(robot)
    body, site = hand.build()
    world = mujoco.MjSpec()
    world.worldbody.add_body(name="hand").add_frame().attach_body(body, "", "")
    model = world.compile()
    data = mujoco.MjData(model)
    for joint, q in hand.open_qpos.items():
        data.qpos[model.jnt_qposadr[model.joint(joint).id]] = q
    mujoco.mj_forward(model, data)
    sid = model.site(site).id
    R, p = data.site_xmat[sid].reshape(3, 3), data.site_xpos[sid]
    boxes = []
    for g in range(model.ngeom):
        if not (model.geom_contype[g] or model.geom_conaffinity[g]):
            continue
        gR = data.geom_xmat[g].reshape(3, 3)
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            mid = model.geom_dataid[g]
            local = model.mesh_vert[model.mesh_vertadr[mid]:model.mesh_vertadr[mid] + model.mesh_vertnum[mid]]
        else:  # boxes (pads) and capsules (Panda fingers): their boxes' corners; others by their bounding sphere
            signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3)
            r, h = model.geom_size[g][:2]
            local = signs * (model.geom_size[g] if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX
                             else [r, r, r + h] if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE
                             else model.geom_rbound[g])
        pts = (data.geom_xpos[g] + local @ gR.T - p) @ R
        lo, hi = pts.min(0), pts.max(0)
        lo[2] -= APPROACH_SWEEP
        boxes.append((lo, hi))
    return np.array(boxes)


def _collides(cloud: np.ndarray, T: np.ndarray, width: float, robot: str) -> bool:
    """Whether the open gripper at TCP pose ``T`` (object frame), on its way in, or its pads closing
    from the open stroke onto the grip of ``width``, hit a surface point of the object."""
    p = (cloud - T[:3, 3]) @ T[:3, :3]
    boxes, hand = hand_boxes(robot), gripper(robot)
    c = HAND_CLEARANCE
    hit = (p[:, None, :] >= boxes[None, :, 0] - c) & (p[:, None, :] <= boxes[None, :, 1] + c)
    if np.any(np.all(hit, axis=2)):
        return True
    x, y, z = np.abs(p[:, 0]), np.abs(p[:, 1]), p[:, 2]
    closing = ((x <= hand.pad_half_width) & (y >= width / 2 + c) & (y <= hand.open_pad_y)
               & (np.abs(z) <= hand.pad_half_length))
    return bool(np.any(closing))


def compute_grasps(uid: str, robot: str) -> np.ndarray:
    """Grasps ``(N, 4, 4)`` of libero object ``uid`` for ``robot``'s hand (module docstring)."""
    from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS

    obj = LIBERO_OBJECTS[uid]
    hand_boxes(robot)  # an unknown robot fails here
    prims = obj.primitives
    com, _ = obj.inertial()
    cloud = surface_points(prims)
    ranked = []
    for width, centre, y, u in _candidates(prims, gripper(robot).max_width):
        for tilt in APPROACH_TILTS_DEG:
            t = math.radians(tilt)
            approach = math.cos(t) * np.array([0.0, 0.0, -1.0]) + math.sin(t) * u
            offset = np.linalg.norm((centre - com)[:2]) + 0.5 * abs(centre[2] - com[2])
            ranked.append((offset + 0.01 * abs(tilt) / 20.0, width, _pose(approach, y, centre)))
    ranked.sort(key=lambda r: r[0])
    kept: list[np.ndarray] = []
    for _, width, T in ranked:
        if len(kept) >= MAX_GRASPS:
            break
        if any(np.linalg.norm(K[:3, 3] - T[:3, 3]) < 0.003 and abs(K[:3, :3][:, 2] @ T[:3, 2]) > 0.99
               and abs(K[:3, 1] @ T[:3, 1]) > 0.99 for K in kept):
            continue
        if not _collides(cloud, T, width, robot):
            kept.append(T)
    if not kept:
        raise ValueError(f"libero object {uid!r}: no collision-free antipodal grasp for the {robot} hand")
    return np.stack(kept)


class LiberoGraspLibrary(GraspLibrary):
    """Grasps of the libero objects: the cached files, computed on first use (module docstring)."""

    def __init__(self, root: str | Path | None = None) -> None:
        super().__init__(root or grasp_dir(), name="libero")
        self.write_root = self.root if root else home_dir()  # no link below it is followed (fileio)

    def _ensure(self, uid: str, robot: str, joint: str | None) -> None:
        from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS

        if joint is None and robot in GRIPPERS and uid in LIBERO_OBJECTS and super().path(uid, robot) is None:
            save_grasp_file(self.root / robot / f"{uid}.npz", compute_grasps(uid, robot), root=self.write_root)

    def path(self, uid: str, robot: str = "franka", joint: str | None = None) -> Path | None:
        self._ensure(uid, robot, joint)
        return super().path(uid, robot, joint)
