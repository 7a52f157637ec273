"""The pick-and-place task family (a task plugin): place in/on, place next to, and by colour.

Success rules: MolmoSpaces' (``molmo_spaces/tasks/pick_and_place*_task.py``), evaluated after
every policy step; docs/success_rules.md puts theirs and ours side by side. Thresholds are the
task spec's fields with the defaults of the spec models below (MolmoSpaces' eval defaults).

``pick_and_place``
    **supported**: the net contact force the receptacle (its whole top-level body) exerts on
    the object is within 30° of vertical and its vertical part carries at least
    ``receptacle_supported_weight_frac`` of the object's weight; failing that, the fallback
    (a contact below the object's box centre whose normal is within 30° of vertical, or the
    object's box centre over the receptacle's box and its base within [-half the receptacle's
    height, +1 cm] of the receptacle's top); failing that, the object's pose in the
    receptacle's frame is within 5 mm / 10° of a pose at which it was supported earlier
    (carry-forward) — **and** no robot body touches the object **and** the receptacle moved at
    most ``max_place_receptacle_pos_displacement`` from ``place_receptacle_start_pose`` and
    tilted at most ``max_place_receptacle_rot_displacement`` (the angle the start-to-now rotation
    turns the world's up axis by: any yaw, about any body axis, is 0 tilt).
``pick_and_place_next_to``
    the XY gap between the two boxes (visible geoms) lies in [``min_surface_to_surface_gap``,
    ``max_surface_to_surface_gap`` + :data:`GAP_TOLERANCE`] **and** both rest on the same
    top-level body (each one's supporting geom: a contact below its box centre whose normal is
    within 80° of vertical; when either has none, the two share a geom whose box top is within
    2 cm of each one's box bottom and covers half its footprint) **and** the receptacle moved at
    most the position limit and turned (any rotation, yaw included) at most the rotation limit.
``pick_and_place_color``
    as ``pick_and_place``; the task first paints the visible geoms of ``object_colors`` (their
    materials cleared), so the instruction's colours are what the cameras see.
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
from pydantic import BeforeValidator, Field
from scipy.spatial.transform import Rotation
from shapely.geometry import Point

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.molmospaces import task_aliases
from molmo_lerobot.benchmark.schema import Pose7, Vec4
from molmo_lerobot.poses import frame_matrix, pose_matrix, unit_pose
from molmo_lerobot.sim import geometry
from molmo_lerobot.tasks.base import Task, TaskType, pose_in_base, pose_names
from molmo_lerobot.tasks.pick import PickTaskSpec

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env

#: slack added to the maximum next-to gap (MolmoSpaces' +0.01 m)
GAP_TOLERANCE = 0.01
#: support: the net contact force must be this close to vertical (MolmoSpaces' 30°)
SUPPORT_MAX_ANGLE = math.radians(30)
#: next-to: a supporting contact's normal must be this close to vertical (MolmoSpaces' 80°)
SURFACE_MAX_ANGLE = math.radians(80)
#: contactless fallback: the object's base may float this far above the receptacle's top
FALLBACK_ABOVE = 0.01
#: next-to without a supporting contact: a geom whose top is this close to a body's bottom may carry it
APPROX_SUPPORT_DZ = 0.02
#: carry-forward tolerances (MolmoSpaces' defaults; an episode may set its own)
CARRY_FORWARD_POS, CARRY_FORWARD_ROT = 0.005, math.radians(10)


# Spec models ------------------------------------------------------------------------------------


class PickAndPlaceTaskSpec(PickTaskSpec):
    """Pick and place: the receptacle carries the object, the robot let go, the receptacle stayed put."""

    place_receptacle_name: str
    place_receptacle_start_pose: Pose7
    receptacle_supported_weight_frac: float = Field(default=0.5, ge=0, le=1)
    max_place_receptacle_pos_displacement: float = Field(default=0.15, ge=0)  # metres
    max_place_receptacle_rot_displacement: float = Field(default=math.radians(60), ge=0)  # radians, yaw ignored


def _gap_default(default: float) -> BeforeValidator:
    """A surface gap in metres; ``null`` in a file means the task's default."""
    return BeforeValidator(lambda v: default if v is None else v)


class PickAndPlaceNextToTaskSpec(PickAndPlaceTaskSpec):
    """Next to: the object ends beside the receptacle, XY surface gap within [min, max]."""

    min_surface_to_surface_gap: Annotated[float, _gap_default(0.0)] = 0.0
    max_surface_to_surface_gap: Annotated[float, _gap_default(0.05)] = 0.05


class PickAndPlaceColorTaskSpec(PickAndPlaceTaskSpec):
    """Pick and place where receptacles are told apart by colour (rgba per object)."""

    object_colors: dict[str, Vec4] | None = None
    other_receptacle_names: list[str] | None = None
    other_receptacle_start_poses: dict[str, Pose7] | None = None


# Helpers -----------------------------------------------------------------------------------------


def tilt(start: np.ndarray, now: np.ndarray) -> float:
    """Radians the rotation from ``start`` to ``now`` (3x3 world rotations) turns the world's up axis."""
    up = (now @ start.T)[:, 2]
    return float(np.arccos(np.clip(up[2], -1.0, 1.0)))


def weight(env: Env, body: int) -> float:
    """Weight (N) of ``body`` and everything below it."""
    return float(env.model.body_subtreemass[body] * np.linalg.norm(env.model.opt.gravity))


# Tasks -------------------------------------------------------------------------------------------


class PickAndPlaceTask[SpecT: PickAndPlaceTaskSpec](Task[SpecT]):
    """Put ``task.pickup_obj_name`` in/on ``task.place_receptacle_name`` (rule: module docstring).

    Environment state: the object's and then the receptacle's pose in the robot base frame."""

    environment_state_names = (*pose_names("object"), *pose_names("receptacle"))

    def __init__(self, spec: SpecT, env: Env) -> None:
        for field, name in (("pickup_obj_name", spec.pickup_obj_name),
                            ("place_receptacle_name", spec.place_receptacle_name)):
            if not name:
                raise ValueError(f"task.{field}: missing (a {type(self).__name__} needs it)")
        self.spec, self.env = spec, env
        m = env.model
        self.object_name = spec.pickup_obj_name
        self.receptacle_name = spec.place_receptacle_name
        self._object = env.body_id(self.object_name, "task.pickup_obj_name")
        self._receptacle = env.body_id(self.receptacle_name, "task.place_receptacle_name")
        if geometry.root_body(m, self._object) != self._object:
            raise ValueError(f"task.pickup_obj_name: {self.object_name!r} is not a top-level body")
        self.object_bodies = env.subtree_bodies(self.object_name)
        self.receptacle_bodies = env.subtree_bodies(self.receptacle_name)
        if self.object_bodies & self.receptacle_bodies:
            raise ValueError("task.place_receptacle_name: the receptacle must not be (part of) the object")
        #: the receptacle's top-level body and everything in it: what "supported by" counts
        self.receptacle_root = geometry.root_body(m, self._receptacle)
        self.receptacle_root_bodies = geometry.subtree(m, self.receptacle_root)
        self.min_support = float(spec.receptacle_supported_weight_frac)
        self.max_pos = float(spec.max_place_receptacle_pos_displacement)
        self.max_rot = float(spec.max_place_receptacle_rot_displacement)
        extra = spec.model_extra or {}  # fields no spec model declares: an episode may carry them
        self.carry_pos = float(extra.get("carry_forward_rel_pos_threshold") or CARRY_FORWARD_POS)
        self.carry_rot = float(extra.get("carry_forward_rel_rot_threshold") or CARRY_FORWARD_ROT)
        self.start_pose: np.ndarray | None = None
        self.supported_rel_poses: list[np.ndarray] = []

    def setup(self) -> None:
        """The receptacle's start pose: ``place_receptacle_start_pose``."""
        self.start_pose = pose_matrix(unit_pose(np.asarray(self.spec.place_receptacle_start_pose, dtype=np.float64)))
        self.supported_rel_poses = []

    def environment_state(self) -> np.ndarray:
        return np.concatenate([pose_in_base(self.env, self._object), pose_in_base(self.env, self._receptacle)])

    # measurements
    def _pose(self, body: int) -> np.ndarray:
        return frame_matrix(self.env.data.xpos[body], self.env.data.xmat[body])

    def support_force(self) -> np.ndarray:
        """Net world contact force (N) the receptacle's top-level body exerts on the object."""
        return geometry.net_contact_force(self.env.model, self.env.data, self.object_bodies,
                                          self.receptacle_root_bodies)

    def support_fraction(self, bodies: frozenset[int] | None = None) -> float:
        """Vertical part of the net contact force from ``bodies`` (default: the receptacle's
        top-level body) over the object's weight."""
        by = self.receptacle_root_bodies if bodies is None else bodies
        force = geometry.net_contact_force(self.env.model, self.env.data, self.object_bodies, by)
        return float(abs(force[2])) / weight(self.env, self._object)

    def supported_by_force(self) -> bool:
        """MolmoSpaces' ``is_object_supported_by_body``: net force within 30° of vertical carrying
        at least ``receptacle_supported_weight_frac`` of the weight."""
        force = self.support_force()
        norm = float(np.linalg.norm(force))
        if norm < 1e-6:
            return False
        vertical = force[2] / norm >= math.cos(SUPPORT_MAX_ANGLE)
        return bool(vertical and abs(force[2]) >= self.min_support * weight(self.env, self._object))

    def supported_by_fallback(self) -> bool:
        """MolmoSpaces' ``objects_on_receptacle`` heuristic (contact below the object's centre with
        a near-vertical normal, or resting on the receptacle's box without contact force)."""
        m, d = self.env.model, self.env.data
        centre, size = geometry.body_aabb(m, d, self._object)
        gb = m.geom_bodyid
        for i in range(d.ncon):
            c = d.contact[i]
            b1, b2 = int(gb[c.geom1]), int(gb[c.geom2])
            if b1 in self.receptacle_bodies and b2 in self.object_bodies:
                normal = c.frame[:3]
            elif b2 in self.receptacle_bodies and b1 in self.object_bodies:
                normal = -c.frame[:3]
            else:
                continue
            normal = normal / np.linalg.norm(normal)
            if c.pos[2] < centre[2] and normal[2] >= math.cos(SUPPORT_MAX_ANGLE):
                return True
        r_centre, r_size = geometry.body_aabb(m, d, self.receptacle_root)
        if not geometry.xy_rect(r_centre, r_size).contains(Point(centre[:2])):
            return False
        base = centre[2] - size[2] / 2
        top = r_centre[2] + r_size[2] / 2
        return bool(-r_size[2] / 2 <= base - top <= FALLBACK_ABOVE)

    def supported(self) -> bool:
        """Force rule, else the fallback, else the carry-forward of a supported relative pose."""
        rel = np.linalg.solve(self._pose(self._receptacle), self._pose(self._object))
        if self.supported_by_force() or self.supported_by_fallback():
            self.supported_rel_poses.append(rel)
            return True
        for seen in self.supported_rel_poses:
            moved = float(np.linalg.norm(rel[:3, 3] - seen[:3, 3]))
            turned = float(Rotation.from_matrix(rel[:3, :3] @ seen[:3, :3].T).magnitude())
            if moved <= self.carry_pos and turned <= self.carry_rot:
                return True
        return False

    def robot_touching(self) -> bool:
        return bool(self.env.contact_bodies(self.object_bodies) & self.env.robot.body_ids)

    def receptacle_displacement(self) -> tuple[float, float, float]:
        """(metres moved, radians tilted, radians turned in all) of the receptacle since the start."""
        if self.start_pose is None:
            raise RuntimeError(f"{type(self).__name__}.setup() must run before success()")
        now = self._pose(self._receptacle)
        moved = float(np.linalg.norm(now[:3, 3] - self.start_pose[:3, 3]))
        turned = float(Rotation.from_matrix(self.start_pose[:3, :3].T @ now[:3, :3]).magnitude())
        return moved, tilt(self.start_pose[:3, :3], now[:3, :3]), turned

    def receptacle_in_place(self) -> bool:
        moved, tilted, _ = self.receptacle_displacement()
        return moved <= self.max_pos and tilted <= self.max_rot

    def success(self) -> bool:
        # supported() runs every step (it remembers supported poses for the carry-forward)
        supported = self.supported()
        return supported and not self.robot_touching() and self.receptacle_in_place()

    def reward(self) -> float:
        return 1.0 if self.success() else 0.0


class PickAndPlaceNextToTask(PickAndPlaceTask[PickAndPlaceNextToTaskSpec]):
    """Put the object beside the receptacle, on the surface the receptacle stands on."""

    def __init__(self, spec: PickAndPlaceNextToTaskSpec, env: Env) -> None:
        super().__init__(spec, env)
        self.min_gap, self.max_gap = float(spec.min_surface_to_surface_gap), float(spec.max_surface_to_surface_gap)
        if self.min_gap > self.max_gap:
            raise ValueError(f"task.min_surface_to_surface_gap {self.min_gap} exceeds "
                             f"task.max_surface_to_surface_gap {self.max_gap}")

    def supporting_root(self, body: int) -> int | None:
        """Top-level body of the geom ``body`` rests on (MolmoSpaces' ``get_supporting_geom``:
        the first contact below the body's box centre whose normal is within 80° of vertical)."""
        m, d = self.env.model, self.env.data
        mine = geometry.subtree(m, geometry.root_body(m, body))
        centre, _ = geometry.body_aabb(m, d, body)
        gb = m.geom_bodyid
        for i in range(d.ncon):
            c = d.contact[i]
            b1, b2 = int(gb[c.geom1]), int(gb[c.geom2])
            if (b1 in mine) == (b2 in mine):
                continue
            other = b2 if b1 in mine else b1
            normal = c.frame[:3] / np.linalg.norm(c.frame[:3])
            if b1 in mine:
                normal = -normal
            if c.pos[2] < centre[2] and normal[2] >= math.cos(SURFACE_MAX_ANGLE):
                return geometry.root_body(m, other)
        return None

    @functools.cached_property
    def _support_candidates(self) -> list[tuple[int, list[int], list[int]]]:
        """(root, visible geoms of its subtree, its own geoms) of every top-level body (the world too)
        that may carry something by boxes: not the robot's, with a visible geom."""
        m = self.env.model
        roots = np.asarray(m.body_rootid)[np.asarray(m.geom_bodyid)]
        out = []
        for root in sorted(set(roots.tolist()) - set(self.env.robot.body_ids)):
            visible = geometry.body_geoms(m, geometry.subtree(m, root))
            if visible:
                out.append((root, visible, np.flatnonzero(roots == root).tolist()))
        return out

    def approximate_supports(self, body: int) -> set[int]:
        """Geoms ``body`` may rest on by boxes alone (MolmoSpaces' ``approximate_supporting_geoms``, the
        fallback when a body has no supporting contact): geoms of the other top-level bodies (not the
        robot's, and only bodies with a visible geom) whose box top is within :data:`APPROX_SUPPORT_DZ`
        of ``body``'s box bottom and whose XY box covers at least half of ``body``'s."""
        m, d = self.env.model, self.env.data
        centre, size = geometry.body_aabb(m, d, body)
        rect, bottom = geometry.xy_rect(centre, size), centre[2] - size[2] / 2
        own = geometry.root_body(m, body)
        out: set[int] = set()
        for root, visible, geoms in self._support_candidates:
            if root == own or not geometry.xy_rect(*geometry.aabb(m, d, visible)).intersects(rect):
                continue
            lo, hi = geometry.geom_boxes(m, d, geoms)
            for i in np.flatnonzero(np.abs(bottom - hi[:, 2]) < APPROX_SUPPORT_DZ):
                footprint = geometry.xy_rect((lo[i] + hi[i]) / 2, hi[i] - lo[i])
                if footprint.intersection(rect).area >= rect.area / 2:
                    out.add(geoms[i])
        return out

    def on_same_surface(self) -> bool:
        """Object and receptacle rest on the same top-level body; when either has no supporting contact,
        on a common geom by :meth:`approximate_supports` (MolmoSpaces' fallback)."""
        under = self.supporting_root(self._object)
        under_receptacle = self.supporting_root(self._receptacle)
        if under is not None and under_receptacle is not None:
            return under == under_receptacle
        return bool(self.approximate_supports(self._object) & self.approximate_supports(self._receptacle))

    def gap(self) -> float:
        """XY gap between the object's and the receptacle's boxes (visible geoms)."""
        m, d = self.env.model, self.env.data
        return geometry.aabb_xy_gap(geometry.body_aabb(m, d, self._object), geometry.body_aabb(m, d, self._receptacle))

    def success(self) -> bool:
        moved, _, turned = self.receptacle_displacement()
        if moved > self.max_pos or turned > self.max_rot:
            return False
        if not self.min_gap <= self.gap() <= self.max_gap + GAP_TOLERANCE:
            return False
        return self.on_same_surface()


class PickAndPlaceColorTask(PickAndPlaceTask[PickAndPlaceColorTaskSpec]):
    """Pick and place among receptacles told apart by colour; paints ``task.object_colors`` on creation."""

    def __init__(self, spec: PickAndPlaceColorTaskSpec, env: Env) -> None:
        super().__init__(spec, env)
        colors = spec.object_colors or {}
        m = env.model  # each Env owns its model copy, so painting never leaks into another episode
        for name, rgba in colors.items():
            env.body_id(name, "task.object_colors")
            for g in geometry.body_geoms(m, env.subtree_bodies(name)):  # visible geoms, as MolmoSpaces
                m.geom_matid[g] = -1
                m.geom_rgba[g] = rgba
        for name in spec.other_receptacle_names or []:
            env.body_id(name, "task.other_receptacle_names")


# Task types --------------------------------------------------------------------------------------


class _PlaceFamily[SpecT: PickAndPlaceTaskSpec](TaskType[SpecT]):
    default_horizon_sec = 40.0

    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        t = self.task_spec(spec)
        return {"receptacle_supported_weight_frac": float(t.receptacle_supported_weight_frac),
                "max_place_receptacle_pos_displacement": float(t.max_place_receptacle_pos_displacement),
                "max_place_receptacle_rot_displacement": float(t.max_place_receptacle_rot_displacement)}


class PickAndPlaceTaskType(_PlaceFamily[PickAndPlaceTaskSpec]):
    name = "pick_and_place"
    aliases = ("molmo_lerobot.tasks.pick_and_place.PickAndPlaceTask", *task_aliases("pick_and_place"))
    spec_model = PickAndPlaceTaskSpec

    def create(self, spec: EpisodeSpec, env: Env) -> PickAndPlaceTask[PickAndPlaceTaskSpec]:
        return PickAndPlaceTask(self.task_spec(spec), env)


class PickAndPlaceNextToTaskType(_PlaceFamily[PickAndPlaceNextToTaskSpec]):
    name = "pick_and_place_next_to"
    aliases = ("molmo_lerobot.tasks.pick_and_place.PickAndPlaceNextToTask", *task_aliases("pick_and_place_next_to"))
    spec_model = PickAndPlaceNextToTaskSpec

    def create(self, spec: EpisodeSpec, env: Env) -> PickAndPlaceNextToTask:
        return PickAndPlaceNextToTask(self.task_spec(spec), env)

    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        t = self.task_spec(spec)
        return {**super().thresholds(spec), "min_surface_to_surface_gap": float(t.min_surface_to_surface_gap),
                "max_surface_to_surface_gap": float(t.max_surface_to_surface_gap),
                "surface_gap_tolerance": GAP_TOLERANCE}


class PickAndPlaceColorTaskType(_PlaceFamily[PickAndPlaceColorTaskSpec]):
    name = "pick_and_place_color"
    aliases = ("molmo_lerobot.tasks.pick_and_place.PickAndPlaceColorTask", *task_aliases("pick_and_place_color"))
    spec_model = PickAndPlaceColorTaskSpec

    def create(self, spec: EpisodeSpec, env: Env) -> PickAndPlaceColorTask:
        return PickAndPlaceColorTask(self.task_spec(spec), env)


@hookimpl
def molmo_task_types() -> list[TaskType[Any]]:
    return [PickAndPlaceTaskType(), PickAndPlaceNextToTaskType(), PickAndPlaceColorTaskType()]
