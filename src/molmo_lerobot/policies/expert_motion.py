"""What the scripted experts share: grasp candidates, IK on the robot alone, and a phased
script played as smooth joint-space moves (:class:`PhasedExpert`)."""

from __future__ import annotations

from collections.abc import Mapping
from functools import cache
from typing import Any

import mink
import mujoco
import numpy as np

from molmo_lerobot.options import validate_group
from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy
from molmo_lerobot.policies.expert_options import ScriptedOptions
from molmo_lerobot.poses import frame_matrix

#: largest per-step change of a joint target in contact (rad): the Panda/FR3 shoulder actuators' force
#: limit over their gain (87 N m / 4500 N m/rad = 0.019 rad) with a margin; see PhasedExpert._path
CONTACT_STEP = 0.015
#: policy steps over which a move in contact speeds up and slows down
CONTACT_RAMP = 4


def object_grasps(env: Any, name: str, catalog: Any) -> np.ndarray:
    """Grasp candidates ``(N, 4, 4)`` in the body frame of scene object ``name``.

    The object's asset UID comes from the scene metadata; its grasps from the grasp
    libraries of ``catalog`` (user libraries first, then the built-in set's generated grasps).
    """
    uid = env.scene_metadata.get("objects", {}).get(name, {}).get("asset_id", name)
    try:
        return robot_grasps(catalog, uid, env.robot_type.hand)
    except LookupError as exc:
        raise ValueError(f"scripted policy: no grasps for object {name!r} (asset {uid!r}): {exc}") from None


#: the robot whose grasps stand in for any other (MolmoSpaces' unified gripper TCP convention:
#: a grasp pose is the TCP pose, +z approach, fingers along ±y, so it transfers between grippers)
FALLBACK_GRASP_ROBOT = "franka"


def robot_grasps(catalog: Any, uid: str, robot: str, joint: str | None = None) -> np.ndarray:
    """Grasps of ``uid`` for ``robot`` in ``catalog``, else those made for :data:`FALLBACK_GRASP_ROBOT`."""
    try:
        return catalog.get_grasps(uid, robot=robot, joint=joint)
    except LookupError:
        if robot == FALLBACK_GRASP_ROBOT:
            raise
        return catalog.get_grasps(uid, robot=FALLBACK_GRASP_ROBOT, joint=joint)


@cache
def _ik_model(robot: Any, base_pose: tuple[float, ...], base_size: tuple[float, ...] | None = None) -> mujoco.MjModel:
    """The robot (its plugin's :class:`~molmo_lerobot.robots.base.RobotType`) alone at its base pose
    on its pedestal (world coordinates, no objects) for IK."""
    world = mujoco.MjSpec()
    if base_size is None:
        robot.add_to(world, base_pose)
    else:
        robot.add_to(world, base_pose, base_size)
    return world.compile()


class IKSolver:
    """Differential IK with mink on the robot alone, for its TCP site, in world coordinates."""

    def __init__(self, robot: Any, base_pose: tuple[float, ...], base_size: tuple[float, ...] | None = None) -> None:
        self.model = _ik_model(robot, base_pose, base_size)
        self.handle = robot.bind(self.model)
        self.scratch = mujoco.MjData(self.model)
        self.config = mink.Configuration(self.model)
        self.frame = mink.FrameTask(self.model.site(self.handle.tcp_site).name, "site", position_cost=1.0,
                                    orientation_cost=0.5, lm_damping=1e-3)
        self.posture = mink.PostureTask(self.model, cost=1e-3)
        self.limits = [mink.ConfigurationLimit(self.model)]

    def solve(self, target: np.ndarray, q_arm: np.ndarray, iters: int = 150,
              tol: tuple[float, float] = (1e-3, 1e-2)) -> np.ndarray | None:
        """Arm joint positions placing the TCP at ``target`` (4x4, world), or None if unreachable."""
        self.handle.set_qpos(self.scratch, "arm", q_arm)
        self.config.update(self.scratch.qpos)
        self.posture.set_target(self.scratch.qpos)
        self.frame.set_target(mink.SE3.from_matrix(target))
        dt = 0.1
        for _ in range(iters):
            err = self.frame.compute_error(self.config)
            if np.linalg.norm(err[:3]) < tol[0] and np.linalg.norm(err[3:]) < tol[1]:
                return self.handle.qpos(self.config.data, "arm")
            vel = mink.solve_ik(self.config, [self.frame, self.posture], dt, solver="daqp", damping=1e-4,
                                limits=self.limits)
            self.config.integrate_inplace(vel, dt)
        return None


def _min_jerk(n: int) -> np.ndarray:
    s = np.arange(1, n + 1) / n
    return 10 * s**3 - 15 * s**4 + 6 * s**5


class PhasedExpert(Policy):
    """Base of the scripted experts: a list of phases, each planned into queued joint targets
    when the queue runs dry, played out in chunks (:class:`ScriptedOptions`: ``chunk``, ``speed``)."""

    needs_images = False
    needs_simulator = True

    def __init__(self, config: Mapping[str, Any]) -> None:
        options = validate_group("policy", ScriptedOptions, config)
        self.chunk, self.speed = options.chunk, float(options.speed)

    def _start(self, ctx: EpisodeContext, phases: list[str]) -> Any:
        """Per-episode state every script shares; returns the (privileged) environment."""
        if ctx.env is None or ctx.catalog is None:
            raise ValueError("scripted policy needs privileged simulator access (EpisodeContext.env and .catalog)")
        env = self.env = ctx.env
        self.catalog = ctx.catalog
        self.dt = ctx.policy_dt_s
        self.ik = IKSolver(env.robot_type, tuple(float(v) for v in env.spec.task.robot_base_pose),
                           env.robot_type.base_size(env.spec.robot))
        self.phases = list(phases)
        self.queue: list[Action] = []
        self.grasp_local: np.ndarray | None = None
        self.q_cmd = env.robot.targets(env.data, "arm")
        self.g_cmd = float(env.robot.targets(env.data, "gripper")[0])
        return env

    def _plan(self, phase: str) -> None:
        """Queue the actions of ``phase`` (the last phase repeats until the episode ends)."""
        raise NotImplementedError

    def _tcp_T(self) -> np.ndarray:
        """Current world pose of the gripper TCP as a 4x4 matrix."""
        site = self.env.robot.tcp_site
        return frame_matrix(self.env.data.site_xpos[site], self.env.data.site_xmat[site])

    def _move(self, q_goal: np.ndarray, gripper: float, min_time: float) -> None:
        """Queue a smooth joint-space move from the last command to ``q_goal``."""
        dq = np.max(np.abs(q_goal - self.q_cmd))
        n = max(1, int(np.ceil(max(min_time, dq / self.speed) / self.dt)))
        for s in _min_jerk(n):
            self.queue.append({"arm": self.q_cmd + s * (q_goal - self.q_cmd),
                               "gripper": np.array([self.g_cmd + s * (gripper - self.g_cmd)])})
        self.q_cmd, self.g_cmd = q_goal.copy(), gripper

    def _path(self, waypoints: list[np.ndarray], gripper: float, duration: float, gentle: bool = False) -> None:
        """Queue one smooth move from the last command through the joint ``waypoints``: piecewise
        linear in joint space, timed by one minimum-jerk profile over the whole path, so the arm
        does not stop at each via-point.

        ``gentle`` (moves in contact): no joint's target changes by more than :data:`CONTACT_STEP`
        in a step, the path timed at that pace (constant, with ramps at both ends). A target
        applied at once and held for the step (``timing.control=hold``) then does not saturate
        the shoulder and elbow actuators; saturated they lose their damping and the arm chatters
        against what it holds (the handle slips out of the fingers)."""
        points = np.array([self.q_cmd, *waypoints])
        reach = np.concatenate([[0.0], np.cumsum(np.max(np.abs(np.diff(points, axis=0)), axis=1))])
        n = max(1, int(np.ceil(max(duration, reach[-1] / self.speed) / self.dt)))
        profile = _min_jerk(n)
        if gentle:
            n = max(n, int(np.ceil(reach[-1] / CONTACT_STEP)) + CONTACT_RAMP)
            pace = np.minimum(1.0, np.minimum(np.arange(1, n + 1), np.arange(n, 0, -1)) / CONTACT_RAMP)
            profile = np.cumsum(pace) / pace.sum()
        for s in profile:
            q = np.array([np.interp(s * reach[-1], reach, points[:, j]) for j in range(points.shape[1])])
            self.queue.append({"arm": q, "gripper": np.array([self.g_cmd + s * (gripper - self.g_cmd)])})
        self.q_cmd, self.g_cmd = points[-1].copy(), gripper

    def act(self, obs: Observation) -> Action:
        while not self.queue:
            phase = self.phases[0] if len(self.phases) == 1 else self.phases.pop(0)
            self._plan(phase)
        chunk, self.queue = self.queue[: self.chunk], self.queue[self.chunk:]
        return {g: np.stack([a[g] for a in chunk]) for g in chunk[0]}
