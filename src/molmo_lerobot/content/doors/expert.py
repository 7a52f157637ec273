"""The scripted door-opening expert (privileged): drive to the door, grasp the handle on the robot's
side, swing the door along its arc moving base and arm together, let go.

Everything comes from the compiled scene: the door's hinge (axis and anchor) and handles
(:func:`molmo_lerobot.tasks.door_opening.door_hinge` / ``door_handles``), the robot base pose from
the simulator. The handle grasped is the one nearest the robot; the grasp holds its bar level,
approaching through the handle towards the leaf (the direction to the other handle), fingers across
the bar. The base moves as the planar ``base`` group (world x, y, yaw targets); the arm follows by
IK on the robot alone with the base frozen where the plan puts it.

Base plan while the door turns by ``dq``:

* pull (the door swings towards the robot): the base turns about the hinge with the leaf, rigidly,
  so the arm keeps its grasp configuration;
* push: the base faces through the doorway and follows the handle into it, between the jambs and
  never nearer the leaf than the leaf's angle leaves room for, as near as that allows to where it
  would stand to grasp the handle (:meth:`ScriptedDoor._push_base`).

Script: drive (to the grasp stand, arm at its start) → reach (pre-grasp 10 cm back) → insert →
close → swing (via-points every :data:`VIA_STEP` rad to :data:`OPEN_GOAL` of the range, paced as
moves in contact) → release → retreat → hold. Needs a robot with a ``base`` move group
(``mobile_franka``).
"""

from __future__ import annotations

import math
from typing import Any

import mink
import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.task_specs import DoorOpeningTaskSpec
from molmo_lerobot.policies.base import EpisodeContext, PolicyType
from molmo_lerobot.policies.expert_motion import CONTACT_STEP, IKSolver, PhasedExpert, _min_jerk
from molmo_lerobot.poses import frame_matrix
from molmo_lerobot.tasks.door_opening import door_handles, door_hinge

PREGRASP_DISTANCE = 0.10
#: opening fraction of the hinge range the expert drives to (success needs 0.67 by default)
OPEN_GOAL = 0.8
VIA_STEP = 0.06
#: horizontal distance from the base centre to the handle where the robot stands to grasp it
STAND = 0.6
#: while pushing: the base's margin from the leaf's free edge (the far jamb), from the turning leaf,
#: and the leaf's half thickness
JAMB_MARGIN, LEAF_MARGIN, LEAF_HALF = 0.07, 0.05, 0.03
#: lanes across the doorway the push plan chooses among
LANES = 9
#: base speeds while driving (m/s, rad/s) and its largest step in contact (m per policy step)
DRIVE_SPEED, TURN_SPEED, BASE_CONTACT_STEP = 0.4, 0.8, 0.012
IK_ITERS = 400
#: the smallest joint-limit margin (fraction of the range) a planned arm configuration may have
MIN_MARGIN = 0.02
#: turns of the last arm joint added to the IK seed, tried in turn for the grasp (rad)
WRIST_SEEDS = (0.0, math.pi / 2, -math.pi / 2)


def _yaw_of(v: np.ndarray) -> float:
    return math.atan2(float(v[1]), float(v[0]))


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


class BaseFrozenIK(IKSolver):
    """Arm IK with the planar base held at a given ``[x, y, yaw]``."""

    def __init__(self, robot: Any, base_pose: tuple[float, ...], base_size: tuple[float, ...] | None) -> None:
        super().__init__(robot, base_pose, base_size)
        names = robot.joint_names.get("base", [])
        dofs = [int(self.model.jnt_dofadr[j]) for j in range(self.model.njnt)
                if self.model.joint(j).name.split("/")[-1] in names]
        if len(dofs) != 3:
            raise ValueError(f"scripted door expert: robot {robot.name!r} has no planar base move group")
        self.freeze = mink.DofFreezingTask(self.model, dof_indices=dofs)

    def solve_at(self, target: np.ndarray, base: np.ndarray, q_arm: np.ndarray) -> np.ndarray | None:
        """Arm joint positions placing the TCP at ``target`` with the base at ``base``, or None."""
        self.handle.set_qpos(self.scratch, "base", base)
        self.handle.set_qpos(self.scratch, "arm", q_arm)
        self.config.update(self.scratch.qpos)
        self.posture.set_target(self.scratch.qpos)
        self.frame.set_target(mink.SE3.from_matrix(target))
        dt = 0.1
        for _ in range(IK_ITERS):
            err = self.frame.compute_error(self.config)
            if np.linalg.norm(err[:3]) < 1e-3 and np.linalg.norm(err[3:]) < 1e-2:
                return self.handle.qpos(self.config.data, "arm")
            vel = mink.solve_ik(self.config, [self.frame, self.posture], dt, solver="daqp", damping=1e-4,
                                limits=self.limits, constraints=[self.freeze])
            self.config.integrate_inplace(vel, dt)
        return None


class ScriptedDoor(PhasedExpert):
    """Door-opening expert: see the module docstring."""

    def reset(self, ctx: EpisodeContext) -> None:
        env = self._start(ctx, ["drive", "reach", "insert", "close", "swing", "release", "retreat", "hold"])
        if "base" not in env.move_groups:
            raise ValueError(f"scripted door expert: robot {env.robot_type.name!r} has no base move group")
        task = env.spec.task
        if not isinstance(task, DoorOpeningTaskSpec):
            raise ValueError(f"scripted door expert: a door_opening episode's task, not {type(task).__name__}")
        #: the hinge's start (the episode's reset state, else 0)
        self.q0 = float(task.articulated_joint_reset_state[0] if task.articulated_joint_reset_state else 0.0)
        self.ik: BaseFrozenIK = BaseFrozenIK(env.robot_type, tuple(float(v) for v in env.spec.task.robot_base_pose),
                               env.robot_type.base_size(env.spec.robot))
        m, d = env.model, env.data
        self.door = env.body_id(env.spec.task.door_body_name, "task.door_body_name")
        self.hinge = door_hinge(m, self.door)
        self.qadr = int(m.jnt_qposadr[self.hinge])
        self.leaf = int(m.jnt_bodyid[self.hinge])
        lo, hi = (env.spec.task.articulated_joint_range or m.jnt_range[self.hinge])
        self.q_goal = float(lo + OPEN_GOAL * (hi - lo))
        self.scratch = mujoco.MjData(m)
        arm_dofs = [j for j in range(self.ik.model.njnt)
                    if self.ik.model.joint(j).name.split("/")[-1] in env.robot_type.joint_names["arm"]]
        self.arm_range = self.ik.model.jnt_range[arm_dofs].T.copy()
        self.b_cmd = env.robot.qpos(d, "base")
        self.anchor = d.xanchor[self.hinge][:2].copy()
        self.axis_sign = float(np.sign(d.xaxis[self.hinge][2]))
        handles = door_handles(m, self.door)
        base_xy = self.b_cmd[:2]
        near = min(handles, key=lambda b: float(np.linalg.norm(d.xpos[b][:2] - base_xy)))
        others = [b for b in handles if b != near]
        h = d.xpos[near].copy()
        approach = (d.xpos[others[0]] - h) if others else (d.xpos[self.leaf] - h)
        approach[2] = 0.0
        approach /= np.linalg.norm(approach)
        self.approach0 = approach
        #: the pushing case: opening moves the handle away from the robot's side of the wall
        turned = self._body_T(float(d.qpos[self.qadr]) + 0.1, near)[:2, 3]
        self.pushing = bool((turned - h[:2]) @ approach[:2] > 0.0)
        self.handle_body = near
        # the grasp: TCP at the bar's centre, +z into the leaf, fingers level across the bar
        z = approach
        y = np.cross([0.0, 0.0, 1.0], z)
        y /= np.linalg.norm(y)
        x = np.cross(y, z)
        leaf_inv = np.linalg.inv(self._body_T())
        #: the two grasps (fingers either way across the bar); ``reach`` keeps the one IK holds best
        self.grasps = []
        for sign in (1.0, -1.0):
            T = np.eye(4)
            T[:3, :3] = np.column_stack([sign * x, sign * y, z])
            T[:3, 3] = h
            self.grasps.append(leaf_inv @ T)
        self.grasp_local = self.grasps[0]
        along = h[:2] - self.anchor
        along -= approach[:2] * float(along @ approach[:2])
        self.leaf_dir = along / np.linalg.norm(along)
        self.half_width = float(env.robot_type.base_size(env.spec.robot)[1]) / 2
        #: the lanes (distance from the hinge along the closed leaf) the base may take through the doorway
        self.lanes = (JAMB_MARGIN + self.half_width, self._leaf_extent() - JAMB_MARGIN - self.half_width)

    # Geometry -----------------------------------------------------------------------------------
    def _body_T(self, q: float | None = None, body: int | None = None) -> np.ndarray:
        m, d = self.env.model, self.scratch
        d.qpos[:] = self.env.data.qpos
        if q is not None:
            d.qpos[self.qadr] = q
        mujoco.mj_kinematics(m, d)
        b = self.leaf if body is None else body
        return frame_matrix(d.xpos[b], d.xmat[b])

    def _leaf_extent(self) -> float:
        """How far the closed leaf reaches from the hinge along it (its geoms' boxes)."""
        m, d = self.env.model, self.env.data
        reach = 0.0
        for g in range(m.ngeom):
            if int(m.geom_bodyid[g]) != self.leaf:
                continue
            centre = d.geom_xpos[g] + d.geom_xmat[g].reshape(3, 3) @ m.geom_aabb[g][:3]
            half = np.abs(d.geom_xmat[g].reshape(3, 3)) @ m.geom_aabb[g][3:]
            reach = max(reach, float((centre[:2] - self.anchor) @ self.leaf_dir + np.abs(self.leaf_dir) @ half[:2]))
        return reach

    def _grasp_T(self, q: float) -> np.ndarray:
        return self._body_T(q) @ self.grasp_local

    def _stand(self) -> np.ndarray:
        """The base pose ``[x, y, yaw]`` to grasp from with the door closed."""
        if self.pushing:
            return self._push_base(float(self.env.data.qpos[self.qadr]))
        h = self._grasp_T(float(self.env.data.qpos[self.qadr]))[:2, 3]
        xy = h - STAND * self.approach0[:2]
        return np.array([xy[0], xy[1], _yaw_of(self.approach0)])

    def _pull_base(self, stand: np.ndarray, dq: float) -> np.ndarray:
        """``stand`` turned about the hinge with the leaf by ``dq``."""
        turn = self.axis_sign * dq
        xy = self.anchor + _rot_z(turn) @ (stand[:2] - self.anchor)
        return np.array([xy[0], xy[1], stand[2] + turn])

    def _push_base(self, q: float) -> np.ndarray:
        """Facing through the doorway, inside it between the jambs (:data:`JAMB_MARGIN` clear), no
        nearer the turned leaf than :data:`LEAF_MARGIN` (the leaf at the base's edge nearer the hinge):
        of the lanes across the doorway, the one that puts the base nearest ``STAND`` behind the handle."""
        tan = math.tan(min(abs(q - self.q0), 1.45))
        out = -self.approach0[:2]  # the robot's side of the wall
        h = self._grasp_T(q)[:2, 3] - self.anchor
        ideal = np.array([float(h @ self.leaf_dir), float(h @ out) + STAND])  # (lane, depth)
        best = None
        for lane in np.linspace(self.lanes[0], self.lanes[1], LANES):
            depth_min = self.half_width + LEAF_MARGIN + LEAF_HALF - max(lane - self.half_width - LEAF_MARGIN, 0.0) * tan
            at = np.array([lane, max(depth_min, ideal[1])])
            if best is None or np.linalg.norm(at - ideal) < np.linalg.norm(best - ideal) - 1e-9:
                best = at
        assert best is not None  # LANES >= 1
        xy = self.anchor + best[0] * self.leaf_dir + best[1] * out
        return np.array([xy[0], xy[1], _yaw_of(self.approach0)])

    # Queueing -----------------------------------------------------------------------------------
    def _queue(self, bases: list[np.ndarray], arms: list[np.ndarray], gripper: float, n: int,
               profile: np.ndarray) -> None:
        """Queue ``n`` steps through the waypoints (piecewise linear, timed by ``profile``)."""
        b_pts = np.array([self.b_cmd, *bases])
        a_pts = np.array([self.q_cmd, *arms])
        k = len(bases)
        for s in profile:
            t = s * k
            i = min(int(t), k - 1)
            f = t - i
            base = b_pts[i] + f * (b_pts[i + 1] - b_pts[i])
            arm = a_pts[i] + f * (a_pts[i + 1] - a_pts[i])
            self.queue.append({"base": base, "arm": arm,
                               "gripper": np.array([self.g_cmd + s * (gripper - self.g_cmd)])})
        self.b_cmd, self.q_cmd, self.g_cmd = b_pts[-1].copy(), a_pts[-1].copy(), gripper

    def _move_all(self, base: np.ndarray, arm: np.ndarray, gripper: float, min_time: float) -> None:
        """A smooth move of base and arm together (min-jerk)."""
        db = self.b_cmd.copy()
        dist = float(np.linalg.norm(base[:2] - db[:2]))
        turn = abs(base[2] - db[2])
        t = max(min_time, dist / DRIVE_SPEED, turn / TURN_SPEED, float(np.max(np.abs(arm - self.q_cmd))) / self.speed)
        n = max(1, int(np.ceil(t / self.dt)))
        self._queue([base], [arm], gripper, n, _min_jerk(n))

    def _gentle(self, bases: list[np.ndarray], arms: list[np.ndarray], gripper: float) -> None:
        """Through the waypoints at contact pace: no arm joint target moves by more than CONTACT_STEP
        and the base by more than BASE_CONTACT_STEP a step, ramped at both ends."""
        b_pts = np.array([self.b_cmd, *bases])
        a_pts = np.array([self.q_cmd, *arms])
        steps = max(float(np.max(np.abs(np.diff(a_pts, axis=0)), initial=0.0)) / CONTACT_STEP,
                    float(np.max(np.linalg.norm(np.diff(b_pts[:, :2], axis=0), axis=1))) / BASE_CONTACT_STEP)
        n = max(4, int(np.ceil(steps * len(bases))) + 4)
        ramp = 4
        pace = np.minimum(1.0, np.minimum(np.arange(1, n + 1), np.arange(n, 0, -1)) / ramp)
        self._queue(bases, arms, gripper, n, np.cumsum(pace) / pace.sum())

    def _margin(self, q_arm: np.ndarray) -> float:
        """The arm's smallest distance to a joint limit, as a fraction of that joint's range."""
        lo, hi = self.arm_range
        return float(np.min(np.minimum(q_arm - lo, hi - q_arm) / (hi - lo)))

    def _plan(self, phase: str) -> None:
        q_door = float(self.env.data.qpos[self.qadr])
        if phase == "drive":
            self.stand = self._stand()
            self._move_all(self.stand, self.q_cmd, 0.0, 1.0)
        elif phase == "reach":
            best: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None
            for grasp, roll in ((g, r) for g in self.grasps for r in WRIST_SEEDS):
                self.grasp_local = grasp
                T = self._grasp_T(q_door)
                T_pre = T.copy()
                T_pre[:3, 3] -= PREGRASP_DISTANCE * T[:3, 2]
                seed = self.q_cmd.copy()
                seed[-1] += roll
                q_pre = self.ik.solve_at(T_pre, self.b_cmd, seed)
                if q_pre is None:
                    continue
                q_at = self.ik.solve_at(T, self.b_cmd, q_pre)
                if q_at is not None and (best is None or self._margin(q_at) > best[0]):
                    best = (self._margin(q_at), grasp, q_pre, q_at)
            if best is None:
                raise RuntimeError("scripted door expert: the handle is out of reach from the grasp stand")
            _, self.grasp_local, q_pre, self.q_grasp = best
            self._move_all(self.b_cmd, q_pre, 0.0, 1.5)
        elif phase == "insert":
            self._move_all(self.b_cmd, self.q_grasp, 0.0, 1.0)
        elif phase == "close":
            self._move_all(self.b_cmd, self.q_cmd, 1.0, 0.6)
            self._move_all(self.b_cmd, self.q_cmd, 1.0, 0.2)
        elif phase == "swing":
            n = max(2, int(np.ceil(abs(self.q_goal - q_door) / VIA_STEP)))
            bases: list[np.ndarray] = []
            arms: list[np.ndarray] = []
            stand, q_arm = self.b_cmd.copy(), self.q_cmd.copy()
            for k in range(1, n + 1):
                q = q_door + (self.q_goal - q_door) * k / n
                base = self._push_base(q) if self.pushing else self._pull_base(stand, q - q_door)
                arm = self.ik.solve_at(self._grasp_T(q), base, arms[-1] if arms else q_arm)
                if arm is None or self._margin(arm) < MIN_MARGIN:
                    break
                bases.append(base)
                arms.append(arm)
            if not bases:
                raise RuntimeError("scripted door expert: cannot follow the handle's arc")
            self._gentle(bases, arms, 1.0)
            self._move_all(self.b_cmd, self.q_cmd, 1.0, 0.3)
        elif phase == "release":
            self._move_all(self.b_cmd, self.q_cmd, 0.0, 0.5)
        elif phase == "retreat":
            T = self._tcp_T()
            T[:3, 3] -= PREGRASP_DISTANCE * T[:3, 2]
            q_back = self.ik.solve_at(T, self.b_cmd, self.q_cmd)
            self._move_all(self.b_cmd, self.q_cmd if q_back is None else q_back, 0.0, 0.8)
        else:  # hold
            self._move_all(self.b_cmd, self.q_cmd, self.g_cmd, self.chunk * self.dt)


@hookimpl
def molmo_experts() -> list[PolicyType]:
    return [PolicyType(name="door_opening", factory=ScriptedDoor,
                       description="drive to the door, grasp the handle, swing it with base and arm")]
