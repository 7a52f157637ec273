"""The scripted place expert for the pick-and-place family (privileged, IK + grasp library).

It picks exactly as :class:`~molmo_lerobot.policies.scripted_pick.ScriptedPick` (grasp choice,
approach, descend, close, lift), then carries the object with the hand's orientation
fixed: up to a height that clears every object on the table (lower where the arm cannot
reach that high), straight across to above the goal, straight down, opens the gripper, and
retreats upwards. Each phase is planned from the current simulator state (where the object
really sits in the hand).

Goal: for ``pick_and_place`` / ``pick_and_place_color`` the object's bottom
:data:`DROP_CLEARANCE` above the receptacle's rim, centred over it; for
``pick_and_place_next_to`` a spot beside the receptacle where the XY surface gap is
:data:`NEXT_TO_GAP`, clear of other objects, inside the workspace, chosen so that the
opening fingers move along the receptacle's edge rather than into it, with the object's
bottom :data:`SET_DOWN_CLEARANCE` above the surface the receptacle stands on.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.scripted_pick import ScriptedPick
from molmo_lerobot.poses import frame_matrix
from molmo_lerobot.sim import geometry
from molmo_lerobot.tasks.pick_and_place import PickAndPlaceNextToTaskSpec, PickAndPlaceTaskSpec

DROP_CLEARANCE = 0.02
SET_DOWN_CLEARANCE = 0.006
#: clearance kept above every other object while carrying
CARRY_CLEARANCE = 0.04
RETREAT_HEIGHT = 0.12
#: fractions of the clearing lift tried, in order, when the arm cannot carry the object at the full one
LOWER_CARRY = (0.75, 0.5, 0.25, 0.0)
NEXT_TO_GAP = 0.02
#: smallest accepted XY gap between the set-down object and any other object
NEIGHBOUR_CLEARANCE = 0.025
#: where the object may be set down, relative to the robot base (x forward, y left)
REACH_X = (0.28, 0.66)
REACH_Y = (-0.32, 0.32)
_DIRECTIONS = 36


def z_extent(env: Any, bodies: frozenset[int]) -> tuple[float, float]:
    """Lowest and highest world z of the collision geoms of ``bodies``."""
    m, d = env.model, env.data
    lo, hi = np.inf, -np.inf
    for g in range(m.ngeom):
        if m.geom_bodyid[g] not in bodies or not (m.geom_contype[g] or m.geom_conaffinity[g]):
            continue
        rot, size, kind = d.geom_xmat[g].reshape(3, 3), m.geom_size[g], m.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_BOX:
            half = float(np.abs(rot[2]) @ size)
        elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            az = abs(rot[2, 2])
            half = az * size[1] + size[0] * np.sqrt(max(0.0, 1 - az * az))
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            half = abs(rot[2, 2]) * size[1] + size[0]
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            half = size[0]
        else:
            half = m.geom_rbound[g]
        z = d.geom_xpos[g][2]
        lo, hi = min(lo, z - half), max(hi, z + half)
    return float(lo), float(hi)


class ScriptedPlace(ScriptedPick):
    """Place expert for ``pick_and_place``, ``pick_and_place_next_to`` and ``pick_and_place_color``."""

    def reset(self, ctx: EpisodeContext) -> None:
        super().reset(ctx)
        task = self.env.spec.task
        if not isinstance(task, PickAndPlaceTaskSpec):
            raise ValueError(f"scripted place expert: a pick-and-place episode's task, not {type(task).__name__}")
        self.receptacle = task.place_receptacle_name
        self.next_to = isinstance(task, PickAndPlaceNextToTaskSpec)
        self.phases = ["approach", "descend", "close", "lift", "carry", "release", "retreat", "hold"]
        self.retries = 1

    # Geometry -------------------------------------------------------------------------------------
    def _tcp(self) -> np.ndarray:
        site = self.env.robot.tcp_site
        return frame_matrix(self.env.data.site_xpos[site], self.env.data.site_xmat[site])

    def _others(self) -> list[frozenset[int]]:
        """Free top-level objects other than the one held (receptacles and distractors), as body sets."""
        env, m = self.env, self.env.model
        skip = env.subtree_bodies(self.target) | env.robot.body_ids
        return [env.subtree_bodies(m.body(b).name) for b in range(1, m.nbody)
                if b not in skip and m.body_jntnum[b] > 0 and m.body_parentid[b] == 0]

    def _footprint(self, bodies: frozenset[int]) -> np.ndarray:
        return geometry.hull_points(geometry.footprint(self.env.model, self.env.data, bodies))

    def _goal_xy(self, turn: float) -> np.ndarray:
        """Where the object's centre (XY) goes, when the hand turns by ``turn`` about the vertical."""
        env = self.env
        rec = env.subtree_bodies(self.receptacle)
        centre = env.data.xpos[env.body_id(self.receptacle)][:2].copy()
        if not self.next_to:
            return centre
        obj_xy = env.data.xpos[env.body_id(self.target)][:2].copy()
        c, s = np.cos(turn), np.sin(turn)
        obj_shape = (self._footprint(env.subtree_bodies(self.target)) - obj_xy) @ np.array([[c, s], [-s, c]])
        rec_shape = geometry.polygon(self._footprint(rec))
        others = [geometry.polygon(self._footprint(o)) for o in self._others() if o != rec]
        fingers = np.array([[c, -s], [s, c]]) @ self._tcp()[:2, 1]
        fingers = fingers / max(np.linalg.norm(fingers), 1e-9)
        base = np.asarray(env.spec.task.robot_base_pose[:2])
        best, best_cost = None, np.inf
        for a in np.arange(_DIRECTIONS) * 2 * np.pi / _DIRECTIONS:
            u = np.array([np.cos(a), np.sin(a)])
            dist = 0.15
            for _ in range(4):  # move along u until the true footprint gap is NEXT_TO_GAP
                gap = geometry.gap(geometry.polygon(obj_shape + centre + dist * u), rec_shape)
                dist += NEXT_TO_GAP - gap
            spot = centre + dist * u
            rel = spot - base
            if not (REACH_X[0] <= rel[0] <= REACH_X[1] and REACH_Y[0] <= rel[1] <= REACH_Y[1]):
                continue
            moved = geometry.polygon(obj_shape + spot)
            clear = min((geometry.gap(moved, q) for q in others), default=1.0)
            if clear < NEIGHBOUR_CLEARANCE:
                continue
            cost = abs(u @ fingers) - 2.0 * min(clear, 0.08) + 0.5 * np.linalg.norm(spot - obj_xy)
            if cost < best_cost:
                best, best_cost = spot, cost
        if best is None:
            raise RuntimeError(f"scripted policy: no free spot next to {self.receptacle!r}")
        return best

    # Planning -------------------------------------------------------------------------------------
    def _carry_and_lower(self, T_up: np.ndarray, T_over: np.ndarray, T_down: np.ndarray) -> None:
        dist = float(np.linalg.norm(T_over[:3, 3] - T_up[:3, 3]))
        self._line(T_up, T_over, self.q_cmd, 1.0, max(0.8, 4 * dist), points=max(4, int(dist / 0.03)))
        self._line(T_over, T_down, self.q_cmd, 1.0, 1.0)
        self._move(self.q_cmd, 1.0, 0.2)  # settle

    def _lift_and_carry(self, T_now: np.ndarray, lift: float, offset: np.ndarray) -> None:
        """Queue the lift by ``lift`` and the carry to above the goal and down onto it; the wrist may not
        reach the goal with the hand's yaw unchanged, so turns of it are tried."""
        T_up = T_now.copy()
        T_up[2, 3] += lift
        if lift > 1e-3:
            self._line(T_now, T_up, self.q_cmd, 1.0, max(0.3, 4 * lift))
        for turn in (0.0, np.pi, np.pi / 2, -np.pi / 2):
            goal = self._goal_xy(turn)
            Rz = np.array([[np.cos(turn), -np.sin(turn), 0.0], [np.sin(turn), np.cos(turn), 0.0], [0, 0, 1]])
            rotated = Rz @ offset
            T_over = T_up.copy()
            T_over[:3, :3] = Rz @ T_up[:3, :3]
            T_over[:2, 3] = goal - rotated[:2]
            T_down = T_over.copy()
            T_down[2, 3] = self.goal_bottom + self.below - rotated[2]
            if self._try(self._carry_and_lower, T_up, T_over, T_down):
                self.T_down = T_down
                return
        raise RuntimeError(f"scripted policy: IK cannot carry {self.target!r} to {self.receptacle!r}")

    def _try(self, plan: Any, *args: Any, **kwargs: Any) -> bool:
        """Queue ``plan(*args)``; on an IK failure undo what it queued and return False."""
        state = (len(self.queue), self.q_cmd.copy(), self.g_cmd)
        try:
            plan(*args, **kwargs)
            return True
        except RuntimeError:
            del self.queue[state[0]:]
            self.q_cmd, self.g_cmd = state[1], state[2]
            return False

    def _plan(self, phase: str) -> None:
        env = self.env
        obj = env.subtree_bodies(self.target)
        if phase == "carry":
            T_now = self._tcp()
            offset = env.data.xpos[env.body_id(self.target)] - T_now[:3, 3]
            bottom, _ = z_extent(env, obj)
            self.below = env.data.xpos[env.body_id(self.target)][2] - bottom  # object centre above its bottom
            rec_lo, rec_hi = z_extent(env, env.subtree_bodies(self.receptacle))
            self.goal_bottom = rec_lo + SET_DOWN_CLEARANCE if self.next_to else rec_hi + DROP_CLEARANCE
            tops = max([z_extent(env, o)[1] for o in self._others()] + [rec_hi])
            lift = max(0.0, tops + CARRY_CLEARANCE - bottom)
            # too high for the arm with the hand's orientation kept: carry lower (less clearance) rather than give up
            for scale in (1.0, *LOWER_CARRY):
                if self._try(self._lift_and_carry, T_now, lift * scale, offset):
                    break
            else:
                raise RuntimeError(f"scripted policy: IK cannot carry {self.target!r} to {self.receptacle!r}")
        elif phase == "descend" and self.retries > 0:
            if not self._try(super()._plan, phase):  # the object was knocked over: choose a grasp again
                self.retries -= 1
                self.phases[:0] = ["approach", "descend"]
        elif phase == "release":
            self._move(self.q_cmd, 0.0, 0.4)
            self._move(self.q_cmd, 0.0, 0.3)
        elif phase == "retreat":
            T_up = self.T_down.copy()
            T_up[2, 3] += RETREAT_HEIGHT
            if not self._try(self._line, self.T_down, T_up, self.q_cmd, 0.0, 0.8):
                self._move(self.q_cmd, 0.0, 0.8)  # the object is already released: stay clear of it
        elif phase == "hold":
            self._move(self.q_cmd, 0.0, self.chunk * self.dt)
        else:
            super()._plan(phase)
