"""Geometry the success rules and experts need, on shapely: AABBs, footprints, gaps, contact forces.

Everything reads a compiled model and its data; nothing here changes the simulation.
"visible" geoms are those in groups 0-2 (what a camera renders), as in MolmoSpaces.
"""

from __future__ import annotations

from collections.abc import Iterable

import mujoco
import numpy as np
import shapely
from shapely.geometry import MultiPoint, Polygon, box

#: points on a circle when a round geom's footprint becomes a polygon
CIRCLE_POINTS = 32
VISIBLE_GROUPS = (0, 1, 2)
_BOX_CORNERS = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])


def root_body(model: mujoco.MjModel, body: int) -> int:
    """The top-level body (child of the world) that ``body`` belongs to."""
    return int(model.body_rootid[body])


def subtree(model: mujoco.MjModel, root: int) -> frozenset[int]:
    """``root`` and every body below it (MuJoCo numbers a parent before its children)."""
    inside = {root}
    for b in range(root + 1, model.nbody):
        if int(model.body_parentid[b]) in inside:
            inside.add(b)
    return frozenset(inside)


def body_geoms(model: mujoco.MjModel, bodies: Iterable[int], visible_only: bool = True,
               collision_only: bool = False) -> list[int]:
    """Geoms of ``bodies`` (visible ones: groups 0-2; collision ones: contype or conaffinity set)."""
    bodies = set(bodies)
    out = []
    for g in range(model.ngeom):
        if int(model.geom_bodyid[g]) not in bodies:
            continue
        if visible_only and int(model.geom_group[g]) not in VISIBLE_GROUPS:
            continue
        if collision_only and not (model.geom_contype[g] or model.geom_conaffinity[g]):
            continue
        out.append(g)
    return out


def geom_points(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> np.ndarray:
    """World points (K, 3) whose convex hull bounds geom ``g`` (mesh vertices; sampled primitive surfaces)."""
    pos, rot, size = data.geom_xpos[g], data.geom_xmat[g].reshape(3, 3), model.geom_size[g]
    kind = model.geom_type[g]
    if kind == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = model.geom_dataid[g]
        start, n = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        local = model.mesh_vert[start:start + n].astype(np.float64)
    elif kind == mujoco.mjtGeom.mjGEOM_BOX:
        local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * size
    else:
        t = np.linspace(0, 2 * np.pi, CIRCLE_POINTS, endpoint=False)
        ring = np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], axis=1)
        if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            local = np.concatenate([ring * size[0] + [0, 0, s * size[1]] for s in (-1, 1)])
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            r = size[0]
            rings = [np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], 1), np.stack([np.cos(t), np.zeros_like(t),
                     np.sin(t)], 1), np.stack([np.zeros_like(t), np.cos(t), np.sin(t)], 1)]
            sphere = np.concatenate(rings) * r
            local = np.concatenate([sphere + np.array([0, 0, s * size[1]]) for s in (-1, 1)])
        elif kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
            rings = [np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], 1), np.stack([np.cos(t), np.zeros_like(t),
                     np.sin(t)], 1), np.stack([np.zeros_like(t), np.cos(t), np.sin(t)], 1)]
            local = np.concatenate(rings) * size
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            rings = [np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], 1), np.stack([np.cos(t), np.zeros_like(t),
                     np.sin(t)], 1), np.stack([np.zeros_like(t), np.cos(t), np.sin(t)], 1)]
            local = np.concatenate(rings) * size[0]
        else:  # planes, height fields: their bounding sphere
            local = np.concatenate([ring, ring[:, [2, 0, 1]]]) * model.geom_rbound[g]
    return pos + local @ rot.T


def geom_boxes(model: mujoco.MjModel, data: mujoco.MjData, geoms: Iterable[int]) -> tuple[np.ndarray, np.ndarray]:
    """World axis-aligned box of each geom as (lows, highs), each (n, 3), as MolmoSpaces' ``geom_aabb``
    bounds a geom: a mesh by its vertices, any other geom by the 8 corners of its local box
    (``model.geom_aabb``) in the world, so a turned sphere or cylinder counts its box's corners."""
    geoms = np.asarray(list(geoms), dtype=int)
    lo, hi = np.empty((len(geoms), 3)), np.empty((len(geoms), 3))
    is_mesh = model.geom_type[geoms] == mujoco.mjtGeom.mjGEOM_MESH
    for i in np.flatnonzero(is_mesh):
        pts = geom_points(model, data, int(geoms[i]))
        lo[i], hi[i] = pts.min(0), pts.max(0)
    boxes = geoms[~is_mesh]
    if len(boxes):
        local = model.geom_aabb[boxes, None, :3] + _BOX_CORNERS * model.geom_aabb[boxes, None, 3:]  # (n, 8, 3)
        world = data.geom_xpos[boxes, None, :] + local @ data.geom_xmat[boxes].reshape(-1, 3, 3).transpose(0, 2, 1)
        lo[~is_mesh], hi[~is_mesh] = world.min(1), world.max(1)
    return lo, hi


def aabb(model: mujoco.MjModel, data: mujoco.MjData, geoms: Iterable[int]) -> tuple[np.ndarray, np.ndarray]:
    """World axis-aligned box of ``geoms`` together as (centre, size) (each geom as :func:`geom_boxes`
    bounds it); ``ValueError`` when there are none."""
    lo, hi = geom_boxes(model, data, geoms)
    if not len(lo):
        raise ValueError("no geoms to bound")
    lo, hi = lo.min(0), hi.max(0)
    return (lo + hi) / 2, hi - lo


def body_aabb(model: mujoco.MjModel, data: mujoco.MjData, body: int) -> tuple[np.ndarray, np.ndarray]:
    """AABB (centre, size) of the visible geoms of ``body``'s subtree (MolmoSpaces' ``body_aabb``);
    its position with zero size when none is visible."""
    geoms = body_geoms(model, subtree(model, body))
    if not geoms:
        return data.xpos[body].copy(), np.zeros(3)
    return aabb(model, data, geoms)


def half_extents_in_body(model: mujoco.MjModel, data: mujoco.MjData, body: int) -> np.ndarray:
    """Half extents (3,) of the box around ``body``'s subtree's collision geoms (visible ones where it
    has none; each as :func:`geom_points` bounds it) along ``body``'s own axes; zeros without geoms."""
    bodies = subtree(model, body)
    geoms = body_geoms(model, bodies, visible_only=False, collision_only=True) or body_geoms(model, bodies)
    if not geoms:
        return np.zeros(3)
    world = np.concatenate([geom_points(model, data, g) for g in geoms])
    local = (world - data.xpos[body]) @ data.xmat[body].reshape(3, 3)
    return (local.max(0) - local.min(0)) / 2


def xy_rect(centre: np.ndarray, size: np.ndarray) -> Polygon:
    """The XY rectangle of an AABB."""
    return box(centre[0] - size[0] / 2, centre[1] - size[1] / 2, centre[0] + size[0] / 2, centre[1] + size[1] / 2)


def aabb_xy_gap(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> float:
    """Surface-to-surface distance between two AABBs in the XY plane (0 when they overlap)."""
    return float(xy_rect(*a).distance(xy_rect(*b)))


def footprint(model: mujoco.MjModel, data: mujoco.MjData, bodies: Iterable[int]) -> Polygon:
    """XY footprint of ``bodies``: the convex hull of their collision geoms projected on the table plane."""
    geoms = body_geoms(model, bodies, visible_only=False, collision_only=True)
    if not geoms:
        raise ValueError(f"body {model.body(min(bodies)).name!r} has no collision geoms")
    return MultiPoint(np.concatenate([geom_points(model, data, g)[:, :2] for g in geoms])).convex_hull


def polygon(points: np.ndarray) -> Polygon:
    """A polygon (the convex hull) from 2-D points (K, 2)."""
    return MultiPoint(np.asarray(points, dtype=np.float64)).convex_hull


def hull_points(shape: Polygon) -> np.ndarray:
    """Vertices (K, 2) of a polygon's exterior (no repeated closing point)."""
    return np.asarray(shape.exterior.coords, dtype=np.float64)[:-1]


def gap(a: Polygon, b: Polygon) -> float:
    """Distance between two shapes (0 when they overlap)."""
    return float(shapely.distance(a, b))


def net_contact_force(model: mujoco.MjModel, data: mujoco.MjData, on: frozenset[int], by: frozenset[int]) \
        -> np.ndarray:
    """World-frame net contact force (N, 3) that bodies ``by`` exert on bodies ``on``."""
    gb = model.geom_bodyid
    force = np.zeros(6)
    net = np.zeros(3)
    for i in range(data.ncon):
        c = data.contact[i]
        b1, b2 = int(gb[c.geom1]), int(gb[c.geom2])
        if b1 in on and b2 in by:
            sign = -1.0  # mj_contactForce gives the force on geom2 (normal from geom1 to geom2)
        elif b2 in on and b1 in by:
            sign = 1.0
        else:
            continue
        mujoco.mj_contactForce(model, data, i, force)
        net += sign * (c.frame.reshape(3, 3).T @ force[:3])
    return net
