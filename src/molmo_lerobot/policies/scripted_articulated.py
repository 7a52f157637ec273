"""The scripted open/close expert: grasp the joint's handle, move it along the joint, let go.

Privileged (``ctx.env``): at reset it reads the articulated object's joint and the handle
grasps of that joint from the grasp library (keyed by asset UID, robot and joint; poses in
the frame of the joint's moving body). It keeps grasps that approach away from the robot and
takes the one whose pre-grasp, grasp and articulation path IK reaches farthest (the first
that reaches all of it); where IK reaches none, it holds still (a failed episode, not an error).
Script:

approach (pre-grasp 10 cm back along the approach) → insert (straight line) → close →
articulate (via-points along the joint's arc or slide axis, each the grasp pose with the
joint moved there, computed with the scene's own kinematics; the path ends early where IK
no longer reaches) → release → retreat (as far as IK reaches, or not at all) → hold.
Open drives the joint to :data:`OPEN_GOAL` of its range, close to fully closed.
"""

from __future__ import annotations

import mujoco
import numpy as np

from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.expert_motion import PhasedExpert, robot_grasps
from molmo_lerobot.poses import frame_matrix

PREGRASP_DISTANCE = 0.10
#: opening fraction the expert drives to when opening (the success threshold is 0.2 by default)
OPEN_GOAL = {"hinge": 0.4, "slide": 0.6}
#: opening fraction commanded when closing (the joint limit stops it at 0)
CLOSE_GOAL = 0.0
#: joint motion per via-point: radians (hinge) or metres (slide)
VIA_STEP = {"hinge": 0.06, "slide": 0.02}
#: seconds per unit of joint motion while articulating (rad or m)
ARTICULATE_TIME = {"hinge": 2.5, "slide": 8.0}
#: IK iterations per target (the level-hand poses here start far from the solver's seed)
IK_ITERS = 400
#: via-points checked along the articulation when choosing among grasps (the one reaching farthest wins)
PLAN_CHECKS = 4
#: lowest accepted cosine between a grasp's approach and the robot-to-handle direction
MIN_APPROACH_COS = 0.5


class ScriptedArticulated(PhasedExpert):
    """Open/close expert: see the module docstring."""

    def reset(self, ctx: EpisodeContext) -> None:
        env = self._start(ctx, ["approach", "insert", "close", "articulate", "release", "retreat", "hold"])
        task = env.spec.task
        self.mode = env.spec.task_name
        self.object_name = task.pickup_obj_name
        m = env.model
        self.joint = -1
        for name in (task.joint_name, f"{self.object_name}/{task.joint_name}"):
            self.joint = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
            if self.joint >= 0:
                break
        if self.joint < 0:
            raise ValueError(f"scripted policy: no joint {task.joint_name!r} on {self.object_name!r}")
        self.local_joint = m.joint(self.joint).name.split("/")[-1]
        self.body = int(m.jnt_bodyid[self.joint])
        self.kind = "hinge" if int(m.jnt_type[self.joint]) == int(mujoco.mjtJoint.mjJNT_HINGE) else "slide"
        self.qadr = int(m.jnt_qposadr[self.joint])
        lo, hi = m.jnt_range[self.joint]
        full = float(hi if abs(hi) >= abs(lo) else lo)  # the fully open end (closed is 0)
        self.q_goal = full * (OPEN_GOAL[self.kind] if self.mode == "open" else CLOSE_GOAL)
        self.scratch = mujoco.MjData(m)

    # Geometry -----------------------------------------------------------------------------------
    def _uid(self) -> str:
        return self.env.scene_metadata.get("objects", {}).get(self.object_name, {}).get("asset_id", self.object_name)

    def _body_T(self, q: float | None = None) -> np.ndarray:
        """World pose of the joint's moving body, now or with the joint at ``q``."""
        m, d = self.env.model, self.scratch
        d.qpos[:] = self.env.data.qpos
        if q is not None:
            d.qpos[self.qadr] = q
        mujoco.mj_kinematics(m, d)
        return frame_matrix(d.xpos[self.body], d.xmat[self.body])

    def _choose_grasp(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(grasp pose in the moving body's frame, pre-grasp arm q) for the first reachable candidate, or None."""
        uid = self._uid()
        try:
            local = robot_grasps(self.catalog, uid, self.env.robot_type.hand, joint=self.local_joint)
        except LookupError as exc:
            raise ValueError(f"scripted policy: no handle grasps for {uid!r} joint {self.local_joint!r}: "
                             f"{exc}") from None
        world = self._body_T() @ local
        base = np.asarray(self.env.spec.task.robot_base_pose[:3])
        out = world[:, :3, 3] - base
        out[:, 2] = 0.0
        out /= np.linalg.norm(out, axis=1, keepdims=True)
        cos = np.einsum("ij,ij->i", world[:, :3, 2], out)
        tcp = self._tcp_T()
        roll_cost = 1.0 - np.abs(world[:, :3, 1] @ tcp[:3, 1])
        order = np.argsort(np.where(cos >= MIN_APPROACH_COS, roll_cost - cos, np.inf), kind="stable")
        q_now = self.env.robot.qpos(self.env.data, "arm")
        best: tuple[int, np.ndarray, np.ndarray] | None = None
        for i in order[: int((cos >= MIN_APPROACH_COS).sum())]:
            T_pre = world[i].copy()
            T_pre[:3, 3] -= PREGRASP_DISTANCE * world[i][:3, 2]
            q_pre = self.ik.solve(T_pre, q_now, iters=IK_ITERS)
            if q_pre is None:
                continue
            q = self.ik.solve(world[i], q_pre, iters=IK_ITERS)
            if q is None:
                continue
            reached = 0
            for T in self._arc(local[i], PLAN_CHECKS):
                q = self.ik.solve(T, q, iters=IK_ITERS)
                if q is None:
                    break
                reached += 1
            if best is None or reached > best[0]:
                best = (reached, local[i], q_pre)
            if reached == PLAN_CHECKS:
                break
        return None if best is None else (best[1], best[2])

    def _arc(self, grasp_local: np.ndarray, n: int) -> list[np.ndarray]:
        """World TCP poses holding ``grasp_local`` with the joint moved in ``n`` steps to its goal."""
        q0 = float(self.env.data.qpos[self.qadr])
        return [self._body_T(q0 + (self.q_goal - q0) * k / n) @ grasp_local for k in range(1, n + 1)]

    # Queueing -----------------------------------------------------------------------------------
    def _via(self, poses: list[np.ndarray], gripper: float, duration: float, partial: bool = False,
             gentle: bool = False) -> None:
        """Queue IK via-points through ``poses`` (world TCP poses), ``duration`` seconds in all.

        With ``partial`` the path stops at the last reachable via-point instead of failing (and
        queues nothing when none is reachable).
        """
        qs = [self.q_cmd]
        for T in poses:
            q = self.ik.solve(T, qs[-1], iters=IK_ITERS)
            if q is None:
                if partial:
                    break
                raise RuntimeError(f"scripted policy: IK failed on the way for {self.object_name!r}")
            qs.append(q)
        if len(qs) == 1:
            return
        self._path(qs[1:], gripper, duration * (len(qs) - 1) / len(poses), gentle)

    def _line(self, T_from: np.ndarray, T_to: np.ndarray, gripper: float, duration: float, points: int = 4,
              partial: bool = False) -> None:
        poses = []
        for k in range(1, points + 1):
            T = T_to.copy()
            T[:3, 3] = T_from[:3, 3] + (T_to[:3, 3] - T_from[:3, 3]) * k / points
            poses.append(T)
        self._via(poses, gripper, duration, partial=partial)

    def _plan(self, phase: str) -> None:
        if phase == "approach":
            chosen = self._choose_grasp()
            if chosen is None:  # no handle grasp IK reaches from here: the expert fails the episode, holding
                self.phases = ["hold"]
                self._move(self.q_cmd, self.g_cmd, self.chunk * self.dt)
                return
            self.grasp_local, q_pre = chosen
            self._move(q_pre, 0.0, 1.0)
        elif phase == "insert":
            T_grasp = self._body_T() @ self.grasp_local
            T_pre = T_grasp.copy()
            T_pre[:3, 3] -= PREGRASP_DISTANCE * T_grasp[:3, 2]
            self.q_cmd = self.env.robot.qpos(self.env.data, "arm")
            self._line(T_pre, T_grasp, 0.0, 1.0)
            self._move(self.q_cmd, 0.0, 2 * self.dt)
        elif phase == "close":
            self._move(self.q_cmd, 1.0, 0.5)
            self._move(self.q_cmd, 1.0, 0.2)
        elif phase == "articulate":
            q0 = float(self.env.data.qpos[self.qadr])
            n = max(2, int(np.ceil(abs(self.q_goal - q0) / VIA_STEP[self.kind])))
            duration = max(1.0, abs(self.q_goal - q0) * ARTICULATE_TIME[self.kind])
            if self.grasp_local is None:
                raise RuntimeError("articulated expert: articulating before a grasp was chosen")
            self._via(self._arc(self.grasp_local, n), 1.0, duration, partial=True, gentle=True)
            self._move(self.q_cmd, 1.0, 0.3)
        elif phase == "release":
            self._move(self.q_cmd, 0.0, 0.5)
        elif phase == "retreat":
            T_now = self._tcp_T()
            T_back = T_now.copy()
            T_back[:3, 3] -= PREGRASP_DISTANCE * T_now[:3, 2]
            self._line(T_now, T_back, 0.0, 0.8, points=2, partial=True)  # as far back as the arm reaches
        else:  # hold
            self._move(self.q_cmd, self.g_cmd, self.chunk * self.dt)
