"""The scripted pick expert (a policy plugin): privileged grasp selection + mink IK.

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

from functools import cache
from typing import Any

import mink
import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.assets.builtin import HANDS, PANDA_HAND
from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyType

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
#: largest per-step change of a joint target in contact (rad): the Panda/FR3 shoulder actuators' force
#: limit over their gain (87 N m / 4500 N m/rad = 0.019 rad) with a margin; see PhasedExpert._path
CONTACT_STEP = 0.015
#: policy steps over which a move in contact speeds up and slows down
CONTACT_RAMP = 4


def _pose_matrix(pose7: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(pose7[3:], dtype=np.float64))
    T[:3, :3] = mat.reshape(3, 3)
    T[:3, 3] = pose7[:3]
    return T


def object_grasps(env: Any, name: str, catalog: Any) -> np.ndarray:
    """Grasp candidates ``(N, 4, 4)`` in the body frame of scene object ``name``.

    The object's asset UID comes from the scene metadata; its grasps from the grasp
    libraries of ``catalog`` (user libraries first, then the built-in set's generated grasps).
    """
    uid = env.scene_metadata.get("objects", {}).get(name, {}).get("asset_id", name)
    try:
        return robot_grasps(catalog, uid, env.robot_type.name)
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
    when the queue runs dry, played out in chunks. Config: ``chunk`` (steps per action chunk),
    ``speed`` (rad/s)."""

    needs_images = False
    needs_simulator = True

    def __init__(self, config: dict[str, Any]) -> None:
        self.chunk = int(config.get("chunk", 12))
        self.speed = float(config.get("speed", 1.0))
        if self.chunk < 1 or self.speed <= 0:
            raise ValueError("scripted policy: chunk must be >= 1 and speed > 0")

    def _start(self, ctx: EpisodeContext, phases: list[str]) -> Any:
        """Per-episode state every script shares; returns the (privileged) environment."""
        if ctx.env is None or ctx.run is None:
            raise ValueError("scripted policy needs privileged simulator access (ctx.env) and the run (ctx.run)")
        env = self.env = ctx.env
        self.catalog = ctx.run.catalog
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
        T = np.eye(4)
        T[:3, :3] = self.env.data.site_xmat[site].reshape(3, 3)
        T[:3, 3] = self.env.data.site_xpos[site]
        return T

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


class ScriptedPick(PhasedExpert):
    """Pick expert: see the module docstring."""

    def reset(self, ctx: EpisodeContext) -> None:
        env = self._start(ctx, ["approach", "descend", "close", "lift", "hold"])
        self.target = env.spec.task.pickup_obj_name

    # Planning -----------------------------------------------------------------------------------
    def _object_T(self) -> np.ndarray:
        return _pose_matrix(self.env.body_pose(self.target))

    def _neighbours(self) -> list[tuple[np.ndarray, float]]:
        """Centres and footprint radii of the other free objects."""
        env, m = self.env, self.env.model
        out = []
        skip = env.subtree_bodies(self.target) | env.robot.body_ids
        for b in range(1, m.nbody):
            if b in skip or m.body_jntnum[b] == 0 or m.body_parentid[b] != 0:
                continue
            geoms = range(m.body_geomadr[b], m.body_geomadr[b] + m.body_geomnum[b])
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
        hand = HANDS.get(env.robot_type.name, PANDA_HAND)  # other robots: fingers as long as the Panda's
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

class ScriptedExpert(Policy):
    """``policy=scripted``: each episode is played by the expert registered for its task type.

    Experts register through the ``molmo_experts`` hook (a PolicyType named after the task
    type it serves); this policy only dispatches, keeping one expert instance per task type.
    """

    needs_images = False
    needs_simulator = True

    def __init__(self, config: dict[str, Any]) -> None:
        self.config = config
        self.experts: dict[str, Policy] = {}
        self.current: Policy | None = None

    def reset(self, ctx: EpisodeContext) -> None:
        if ctx.run is None:
            raise ValueError("scripted policy needs privileged simulator access (ctx.env) and the run (ctx.run)")
        plugins = ctx.run.plugins
        task_type = plugins.task_type(ctx.spec.task_name)
        if task_type.name not in self.experts:
            try:
                expert = plugins.expert(task_type.name)
            except LookupError:
                raise ValueError(f"scripted policy: no scripted expert serves task type {task_type.name!r}") from None
            self.experts[task_type.name] = expert.factory(self.config)
        self.current = self.experts[task_type.name]
        self.current.reset(ctx)

    def act(self, obs: Observation) -> Action:
        if self.current is None:
            raise RuntimeError("scripted policy: act() before reset()")
        return self.current.act(obs)

    def close(self) -> None:
        for expert in self.experts.values():
            expert.close()


@hookimpl
def molmo_experts() -> list[PolicyType]:
    from molmo_lerobot.policies.scripted_articulated import ScriptedArticulated
    from molmo_lerobot.policies.scripted_place import ScriptedPlace

    return [PolicyType(name="pick", factory=ScriptedPick, description="grasp library + IK, lift"),
            PolicyType(name="pick_and_place", aliases=("pick_and_place_next_to", "pick_and_place_color"),
                       factory=ScriptedPlace, description="pick, carry, place, release"),
            PolicyType(name="open", aliases=("close",), factory=ScriptedArticulated,
                       description="grasp the handle, move it along the joint")]


@hookimpl
def molmo_policies() -> list[PolicyType]:
    return [PolicyType(name="scripted", factory=ScriptedExpert,
                       description="privileged expert of each episode's task type (IK + grasp library)")]
