"""The scripted pick expert: privileged grasp selection + mink IK.

At reset it reads the target object's pose from the simulator (``ctx.env``), turns the
object's grasp candidates into world poses, keeps those that approach from above, keep
the fingertips off the table and the fingers clear of neighbouring objects, and takes the
first (closest to the current wrist yaw) that IK reaches. It then plays a fixed script,
re-planning each phase from the current state:

approach (pre-grasp 10 cm back along the approach) → descend (straight line) → close →
lift (straight up) → hold. Joint targets follow a smooth (minimum-jerk) profile and are
returned as chunks, so the environment renders only at chunk ends.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from molmo_lerobot.assets.builtin import HandGeometry
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.expert_motion import PhasedExpert, object_grasps
from molmo_lerobot.poses import pose_matrix

if TYPE_CHECKING:
    from molmo_lerobot.robots.base import RobotType

PREGRASP_DISTANCE = 0.10
LIFT_HEIGHT = 0.12
#: the approach passes this far (m) above the pre-grasp and comes straight down onto it
APPROACH_ABOVE = 0.08
#: steepest accepted approach tilt from straight down
MAX_TILT_DEG = 40.0
#: clearance kept between open fingers and neighbouring objects / between fingertips and the support
FINGER_CLEARANCE = 0.012
TABLE_CLEARANCE = 0.004
#: seconds the arm is given to settle on a pose before a move that starts in or near contact
SETTLE_S = 0.3


def hand_geometry(robot_type: RobotType) -> HandGeometry:
    """The robot's gripper geometry (``RobotType.hand_geometry``); ``ValueError`` naming a robot without one."""
    hand = robot_type.hand_geometry
    if hand is None:
        raise ValueError(f"scripted pick: robot {robot_type.name!r} has no hand geometry (RobotType.hand_geometry), "
                         "which its grasp planning needs")
    return hand


class ScriptedPick(PhasedExpert):
    """Pick expert: see the module docstring."""

    def reset(self, ctx: EpisodeContext) -> None:
        env = self._start(ctx, ["approach", "descend", "close", "lift", "hold"])
        self.target = env.spec.task.pickup_obj_name
        self.hand = hand_geometry(env.robot_type)

    # Planning -----------------------------------------------------------------------------------
    def _object_T(self) -> np.ndarray:
        return pose_matrix(self.env.body_pose(self.target))

    def _neighbours(self) -> list[tuple[np.ndarray, float]]:
        """Centres and footprint radii (of their collision geoms) of the other free objects."""
        env, m = self.env, self.env.model
        out = []
        skip = env.subtree_bodies(self.target) | env.robot.body_ids
        for b in range(1, m.nbody):
            if b in skip or m.body_jntnum[b] == 0 or m.body_parentid[b] != 0:
                continue
            geoms = [g for g in range(m.body_geomadr[b], m.body_geomadr[b] + m.body_geomnum[b])
                     if m.geom_contype[g] or m.geom_conaffinity[g]]
            radius = max((m.geom_rbound[g] + np.linalg.norm(m.geom_pos[g]) for g in geoms), default=0.0)
            out.append((env.data.xpos[b].copy(), float(radius)))
        return out

    def _choose_grasp(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(grasp pose in object frame, pre-grasp arm q, grasp arm q) for the best feasible candidate."""
        env = self.env
        T_obj = self._object_T()
        local = object_grasps(env, self.target, self.catalog)
        world = T_obj @ local
        approach = world[:, :3, 2]
        down = -approach[:, 2]
        hand = self.hand
        tips = world[:, :3, 3] + hand.tcp_to_fingertip * approach
        support = self._support_height(T_obj)
        ok = (down >= np.cos(np.radians(MAX_TILT_DEG))) & (tips[:, 2] >= support + TABLE_CLEARANCE)
        fingers = world[:, :3, 1]
        for centre, radius in self._neighbours():
            for sign in (1.0, -1.0):
                tip_xy = (world[:, :3, 3] + sign * hand.open_half_span * fingers)[:, :2]
                ok &= np.linalg.norm(tip_xy - centre[:2], axis=1) >= radius + FINGER_CLEARANCE
        if not ok.any():
            raise RuntimeError(f"scripted policy: no collision-free top grasp for {self.target!r}")
        tcp = env.data.site_xmat[env.robot.tcp_site].reshape(3, 3)
        yaw_cost = 1.0 - np.abs(fingers @ tcp[:, 1])  # the hand is symmetric: ±y are equal
        tilt_cost = 1.0 - down
        order = np.argsort(np.where(ok, yaw_cost + 2.0 * tilt_cost, np.inf), kind="stable")
        q_now = env.robot.qpos(env.data, "arm")
        for i in order[: int(ok.sum())]:
            T_grasp = world[i]
            T_pre = T_grasp.copy()
            T_pre[:3, 3] -= PREGRASP_DISTANCE * T_grasp[:3, 2]
            q_pre = self.ik.solve(T_pre, q_now)
            if q_pre is None:
                continue
            q_grasp = self.ik.solve(T_grasp, q_pre)
            if q_grasp is not None:
                return local[i], q_pre, q_grasp
        raise RuntimeError(f"scripted policy: IK found no reachable grasp for {self.target!r}")

    def _support_height(self, T_obj: np.ndarray) -> float:
        """Lowest point of the object's bounding box: the surface it rests on."""
        m, b = self.env.model, self.env.body_id(self.target)
        geoms = range(m.body_geomadr[b], m.body_geomadr[b] + m.body_geomnum[b])
        return float(min(T_obj[2, 3] + m.geom_pos[g][2] - m.geom_rbound[g] for g in geoms)
                     if m.body_geomnum[b] else T_obj[2, 3])

    def _line(self, T_from: np.ndarray, T_to: np.ndarray, q_seed: np.ndarray, gripper: float, duration: float,
              points: int = 4) -> None:
        """Queue a straight TCP line (IK at ``points`` via-points, fixed orientation), one smooth
        move; holding the object (gripper closed) it is a move in contact (``_path``'s ``gentle``)."""
        qs = [q_seed]
        for k in range(1, points + 1):
            T = T_to.copy()
            T[:3, 3] = T_from[:3, 3] + (T_to[:3, 3] - T_from[:3, 3]) * k / points
            q = self.ik.solve(T, qs[-1])
            if q is None:
                raise RuntimeError(f"scripted policy: IK failed on the straight line for {self.target!r}")
            qs.append(q)
        self._path(qs[1:], gripper, duration, gentle=gripper > 0.5)

    def _plan(self, phase: str) -> None:
        env = self.env
        if phase == "approach":
            self.grasp_local, q_pre, _ = self._choose_grasp()
            T_pre = self._object_T() @ self.grasp_local
            T_pre[:3, 3] -= PREGRASP_DISTANCE * T_pre[:3, 2]
            T_above = T_pre.copy()
            T_above[2, 3] += APPROACH_ABOVE
            q_above = self.ik.solve(T_above, q_pre)
            if q_above is None:
                self._move(q_pre, 0.0, 1.0)
            else:  # come down onto the pre-grasp: a joint-space sweep straight to it may clip the object
                self._move(q_above, 0.0, 1.0)
                self._line(T_above, T_pre, q_above, 0.0, 0.4, points=2)
            self._move(self.q_cmd, 0.0, SETTLE_S)  # arrive at the pre-grasp before descending past neighbours
        elif phase == "descend":
            T_grasp = self._object_T() @ self.grasp_local  # the object may have been nudged
            T_pre = T_grasp.copy()
            T_pre[:3, 3] -= PREGRASP_DISTANCE * T_grasp[:3, 2]
            self._line(T_pre, T_grasp, env.robot.qpos(env.data, "arm"), 0.0, 1.0)
            self._move(self.q_cmd, 0.0, 2 * self.dt)  # settle
        elif phase == "close":
            self._move(self.q_cmd, 1.0, 0.5)
            self._move(self.q_cmd, 1.0, 0.2)
        elif phase == "lift":
            T_now = self._tcp_T()
            T_up = T_now.copy()
            T_up[2, 3] += LIFT_HEIGHT
            self._line(T_now, T_up, self.q_cmd, 1.0, 1.2)
        else:  # hold
            self._move(self.q_cmd, 1.0, self.chunk * self.dt)
