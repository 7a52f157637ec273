"""The pick-and-place task family (a task plugin): place in/on, place next to, and by colour.

Success rules (MolmoSpaces', evaluated every policy step; thresholds are the task spec's
fields with the defaults of :mod:`molmo_lerobot.benchmark.schema`):

``pick_and_place``
    the receptacle carries at least ``receptacle_supported_weight_frac`` of the object's
    weight (vertical components of the contact normal forces from ``mj_contactForce``
    between the two, over the object's weight) **and** no robot body touches the object
    **and** the receptacle moved at most ``max_place_receptacle_pos_displacement`` metres
    and tilted at most ``max_place_receptacle_rot_displacement`` radians (the angle between
    its start and current up axes, so yaw is ignored) since the start.
``pick_and_place_next_to``
    the XY surface-to-surface gap between object and receptacle (footprints projected on
    the table, each the convex hull of its collision geoms) lies in
    [``min_surface_to_surface_gap``, ``max_surface_to_surface_gap`` + :data:`GAP_TOLERANCE`]
    **and** object and receptacle rest on the same body (the one carrying at least
    ``receptacle_supported_weight_frac`` of each one's weight; the robot never counts, so
    the object must have been released) **and** the receptacle stayed within the same
    displacement limits.
``pick_and_place_color``
    as ``pick_and_place``; the task paints the bodies of ``object_colors`` first, so the
    instruction's colours are what the cameras see.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.molmospaces import task_aliases
from molmo_lerobot.benchmark.schema import PickAndPlaceNextToTaskSpec, PickAndPlaceTaskSpec
from molmo_lerobot.tasks.base import Task, TaskType

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env

#: slack added to the maximum next-to gap (MolmoSpaces' +0.01 m)
GAP_TOLERANCE = 0.01
#: points on each circle when a round geom's footprint is made a polygon
_CIRCLE_POINTS = 32

_PLACE_FIELDS = ("receptacle_supported_weight_frac", "max_place_receptacle_pos_displacement",
                 "max_place_receptacle_rot_displacement")
_GAP_FIELDS = ("min_surface_to_surface_gap", "max_surface_to_surface_gap")


def _resolved(spec: EpisodeSpec, fields: tuple[str, ...], model: type) -> dict[str, float]:
    """Each field from the episode's task, else the schema's default."""
    out = {}
    for name in fields:
        value = getattr(spec.task, name, None)
        out[name] = float(model.model_fields[name].default if value is None else value)
    return out


# Simulator measurements --------------------------------------------------------------------------


def upward_forces(env: Env, bodies: frozenset[int]) -> dict[int, float]:
    """Per other body, the upward (world +z) part of the contact normal forces it exerts on ``bodies``."""
    m, d = env.model, env.data
    gb = m.geom_bodyid
    out: dict[int, float] = {}
    force = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        b1, b2 = int(gb[c.geom1]), int(gb[c.geom2])
        if (b1 in bodies) == (b2 in bodies):
            continue
        mujoco.mj_contactForce(m, d, i, force)
        # the normal (frame row 0) points from geom1 to geom2; the normal force pushes geom2 along it
        up = force[0] * c.frame[2]
        other, up = (b1, up) if b2 in bodies else (b2, -up)
        out[other] = out.get(other, 0.0) + float(up)
    return out


def weight(env: Env, body: int) -> float:
    """Weight (N) of ``body`` and everything below it."""
    return float(env.model.body_subtreemass[body] * np.linalg.norm(env.model.opt.gravity))


def _geom_footprint(m: mujoco.MjModel, d: mujoco.MjData, g: int) -> np.ndarray:
    """Points (K, 2) whose convex hull is the XY projection of geom ``g``."""
    pos, rot, size = d.geom_xpos[g], d.geom_xmat[g].reshape(3, 3), m.geom_size[g]
    kind = m.geom_type[g]
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * size
        return (pos + corners @ rot.T)[:, :2]
    t = np.linspace(0, 2 * np.pi, _CIRCLE_POINTS, endpoint=False)
    circle = np.stack([np.cos(t), np.sin(t)], axis=1)
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:  # both rims of the caps, in 3D, projected
        rim = np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], axis=1) * size[0]
        caps = [rim + [0.0, 0.0, s * size[1]] for s in (-1, 1)]
        return (pos + np.concatenate(caps) @ rot.T)[:, :2]
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        ends = [pos + s * size[1] * rot[:, 2] for s in (-1, 1)]
        return np.concatenate([e[:2] + size[0] * circle for e in ends])
    radius = size[0] if kind == mujoco.mjtGeom.mjGEOM_SPHERE else m.geom_rbound[g]
    return pos[:2] + radius * circle


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise) of 2-D points (Andrew's monotone chain)."""
    pts = sorted(set(map(tuple, np.round(points, 9).tolist())))
    if len(pts) < 3:
        return np.asarray(pts, dtype=float).reshape(-1, 2)

    def half(seq: list) -> list:
        out: list = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out[:-1]

    return np.asarray(half(pts) + half(pts[::-1]), dtype=float)


def _separated(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test for two convex polygons (counter-clockwise vertices)."""
    edges = np.concatenate([np.roll(a, -1, axis=0) - a, np.roll(b, -1, axis=0) - b])
    normals = np.stack([-edges[:, 1], edges[:, 0]], axis=1)
    pa, pb = a @ normals.T, b @ normals.T
    return bool(np.any((pa.max(0) < pb.min(0)) | (pb.max(0) < pa.min(0))))


def _point_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances from points ``p`` (N, 2) to every segment ``a[k]``-``b[k]`` (K, 2): (N, K)."""
    ab = b - a
    t = np.clip(((p[:, None, :] - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-18), 0.0, 1.0)
    return np.linalg.norm(p[:, None, :] - (a + t[..., None] * ab), axis=-1)


def polygon_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Distance between two convex polygons given counter-clockwise (0 when they overlap)."""
    if not _separated(a, b):
        return 0.0
    return float(min(_point_segment(a, b, np.roll(b, -1, axis=0)).min(),
                     _point_segment(b, a, np.roll(a, -1, axis=0)).min()))


def footprint(env: Env, bodies: frozenset[int]) -> np.ndarray:
    """The XY footprint of ``bodies``: convex hull of their collision geoms projected on the table plane."""
    m = env.model
    geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] in bodies and (m.geom_contype[g] or m.geom_conaffinity[g])]
    if not geoms:
        raise ValueError(f"body {m.body(min(bodies)).name!r} has no collision geoms")
    return _hull(np.concatenate([_geom_footprint(m, env.data, g) for g in geoms]))


def surface_gap(env: Env, a: frozenset[int], b: frozenset[int]) -> float:
    """XY surface-to-surface gap between the footprints of two sets of bodies (0 when they overlap)."""
    return polygon_gap(footprint(env, a), footprint(env, b))


# Tasks -------------------------------------------------------------------------------------------


class PickAndPlaceTask(Task):
    """Put ``task.pickup_obj_name`` in/on ``task.place_receptacle_name`` (rule: module docstring)."""

    def __init__(self, spec: EpisodeSpec, env: Env) -> None:
        for field in ("pickup_obj_name", "place_receptacle_name"):
            if not getattr(spec.task, field, None):
                raise ValueError(f"task.{field}: missing (a {type(self).__name__} needs it)")
        self.env = env
        self.object_name = spec.task.pickup_obj_name
        self.receptacle_name = spec.task.place_receptacle_name
        self._object = env.body_id(self.object_name, "task.pickup_obj_name")
        self._receptacle = env.body_id(self.receptacle_name, "task.place_receptacle_name")
        self.object_bodies = env.subtree_bodies(self.object_name)
        self.receptacle_bodies = env.subtree_bodies(self.receptacle_name)
        if self.object_bodies & self.receptacle_bodies:
            raise ValueError("task.place_receptacle_name: the receptacle must not be (part of) the object")
        t = _resolved(spec, _PLACE_FIELDS, PickAndPlaceTaskSpec)
        self.min_support = t["receptacle_supported_weight_frac"]
        self.max_pos = t["max_place_receptacle_pos_displacement"]
        self.max_rot = t["max_place_receptacle_rot_displacement"]
        self.start_pos: np.ndarray | None = None
        self.start_up: np.ndarray | None = None

    def setup(self) -> None:
        d = self.env.data
        self.start_pos = d.xpos[self._receptacle].copy()
        self.start_up = d.xmat[self._receptacle].reshape(3, 3)[:, 2].copy()

    # measurements
    def support_fraction(self, bodies: frozenset[int] | None = None) -> float:
        """Fraction of the object's weight carried by ``bodies`` (default: the receptacle)."""
        bodies = self.receptacle_bodies if bodies is None else bodies
        carried = sum(f for b, f in upward_forces(self.env, self.object_bodies).items() if b in bodies)
        return carried / weight(self.env, self._object)

    def robot_touching(self) -> bool:
        return bool(self.env.contact_bodies(self.object_bodies) & self.env.robot.body_ids)

    def receptacle_displacement(self) -> tuple[float, float]:
        """(metres moved, radians tilted) of the receptacle since ``setup``; yaw does not count."""
        if self.start_pos is None or self.start_up is None:
            raise RuntimeError(f"{type(self).__name__}.setup() must run before success()")
        d = self.env.data
        up = d.xmat[self._receptacle].reshape(3, 3)[:, 2]
        tilt = math.acos(float(np.clip(up @ self.start_up, -1.0, 1.0)))
        return float(np.linalg.norm(d.xpos[self._receptacle] - self.start_pos)), tilt

    def receptacle_in_place(self) -> bool:
        moved, tilted = self.receptacle_displacement()
        return moved <= self.max_pos and tilted <= self.max_rot

    def success(self) -> bool:
        return (self.receptacle_in_place() and not self.robot_touching()
                and self.support_fraction() >= self.min_support)

    def reward(self) -> float:
        return 1.0 if self.success() else 0.0


class PickAndPlaceNextToTask(PickAndPlaceTask):
    """Put the object beside the receptacle, on the surface the receptacle stands on."""

    def __init__(self, spec: EpisodeSpec, env: Env) -> None:
        super().__init__(spec, env)
        gaps = _resolved(spec, _GAP_FIELDS, PickAndPlaceNextToTaskSpec)
        self.min_gap, self.max_gap = gaps["min_surface_to_surface_gap"], gaps["max_surface_to_surface_gap"]
        if self.min_gap > self.max_gap:
            raise ValueError(f"task.min_surface_to_surface_gap {self.min_gap} exceeds "
                             f"task.max_surface_to_surface_gap {self.max_gap}")

    def supporting_body(self, bodies: frozenset[int], root: int) -> int | None:
        """The non-robot body carrying at least ``min_support`` of ``root``'s weight, if any."""
        forces = {b: f for b, f in upward_forces(self.env, bodies).items() if b not in self.env.robot.body_ids}
        if not forces:
            return None
        best = max(forces, key=forces.__getitem__)
        return best if forces[best] >= self.min_support * weight(self.env, root) else None

    def gap(self) -> float:
        return surface_gap(self.env, self.object_bodies, self.receptacle_bodies)

    def success(self) -> bool:
        if not self.receptacle_in_place() or self.robot_touching():
            return False
        under = self.supporting_body(self.object_bodies, self._object)
        if under is None or under != self.supporting_body(self.receptacle_bodies, self._receptacle):
            return False
        return self.min_gap <= self.gap() <= self.max_gap + GAP_TOLERANCE


class PickAndPlaceColorTask(PickAndPlaceTask):
    """Pick and place among receptacles told apart by colour; paints ``task.object_colors`` on creation."""

    def __init__(self, spec: EpisodeSpec, env: Env) -> None:
        super().__init__(spec, env)
        colors = getattr(spec.task, "object_colors", None) or {}
        m = env.model  # each Env owns its model copy, so painting never leaks into another episode
        for name, rgba in colors.items():
            env.body_id(name, "task.object_colors")
            bodies = env.subtree_bodies(name)
            for g in range(m.ngeom):
                if m.geom_bodyid[g] in bodies:
                    m.geom_rgba[g] = rgba
        for name in getattr(spec.task, "other_receptacle_names", None) or []:
            env.body_id(name, "task.other_receptacle_names")


# Task types --------------------------------------------------------------------------------------


class _PlaceFamily(TaskType):
    default_horizon_sec = 40.0
    task_class: type[PickAndPlaceTask]
    spec_model: type = PickAndPlaceTaskSpec
    fields: tuple[str, ...] = _PLACE_FIELDS

    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        return _resolved(spec, self.fields, self.spec_model)

    def create(self, spec: EpisodeSpec, env: Env) -> PickAndPlaceTask:
        return self.task_class(spec, env)


class PickAndPlaceTaskType(_PlaceFamily):
    name = "pick_and_place"
    aliases = ("molmo_lerobot.tasks.pick_and_place.PickAndPlaceTask", *task_aliases("pick_and_place"))
    task_class = PickAndPlaceTask


class PickAndPlaceNextToTaskType(_PlaceFamily):
    name = "pick_and_place_next_to"
    aliases = ("molmo_lerobot.tasks.pick_and_place.PickAndPlaceNextToTask", *task_aliases("pick_and_place_next_to"))
    task_class = PickAndPlaceNextToTask
    spec_model = PickAndPlaceNextToTaskSpec
    fields = _PLACE_FIELDS + _GAP_FIELDS

    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        return {**super().thresholds(spec), "surface_gap_tolerance": GAP_TOLERANCE}


class PickAndPlaceColorTaskType(_PlaceFamily):
    name = "pick_and_place_color"
    aliases = ("molmo_lerobot.tasks.pick_and_place.PickAndPlaceColorTask", *task_aliases("pick_and_place_color"))
    task_class = PickAndPlaceColorTask


@hookimpl
def molmo_task_types() -> list[TaskType]:
    return [PickAndPlaceTaskType(), PickAndPlaceNextToTaskType(), PickAndPlaceColorTaskType()]
