"""The scripted navigation expert (``nav_to_obj``): privileged occupancy-grid planning, then drive.

At reset it reads the scene from the simulator (``ctx.env``): an occupancy grid of every colliding
geom but the robot's (:mod:`molmo_lerobot.sim.navigation`), inflated by the robot's footprint
radius (the farthest reach of its geoms from the base centre in the start pose, plus
:data:`MARGIN`), so any yaw is safe where the base centre is free. Goal cells lie
:data:`GOAL_DISTANCE` from a target candidate (below the task's ``succ_pos_threshold``) with no wall
between them and it; the shortest 8-connected path from the base to any goal cell (Dijkstra over
the free cells) picks the candidate. The base then follows the path at :data:`SPEED` while turning
(at most :data:`TURN_RATE`) to face that candidate, so the head camera sees it on arrival; arm and
gripper hold their start targets. The whole trajectory is planned at reset and played in chunks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.task_specs import NavToObjTaskSpec
from molmo_lerobot.options import validate_group
from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyType
from molmo_lerobot.policies.expert_options import ScriptedOptions
from molmo_lerobot.sim.navigation import Grid, descend, free_space, geom_boxes, occupancy, path_lengths
from molmo_lerobot.tasks.nav_to_obj import candidate_names

#: base speed (m/s), turn rate (rad/s), clearance added to the footprint radius (m)
SPEED, TURN_RATE, MARGIN = 0.6, 1.2, 0.06
#: goal ring around a target (m from it, planar): close enough to pass, far enough to see it
GOAL_DISTANCE = (0.55, 1.2)


def footprint_radius(env: Any) -> float:
    """The farthest planar reach of the robot's geoms from its base centre, in the current state."""
    base = env.robot.qpos(env.data, "base")[:2]
    m, d = env.model, env.data
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    reach = 0.0
    for g in range(m.ngeom):
        if int(m.geom_bodyid[g]) in env.robot.body_ids:
            local = corners * m.geom_aabb[g][3:] + m.geom_aabb[g][:3]
            world = local @ d.geom_xmat[g].reshape(3, 3).T + d.geom_xpos[g]
            reach = max(reach, float(np.linalg.norm(world[:, :2] - base, axis=1).max()))
    return reach


class ScriptedNav(Policy):
    """Nav expert: see the module docstring (:class:`ScriptedOptions`: ``chunk``)."""

    needs_images = False
    needs_simulator = True

    def __init__(self, config: Mapping[str, Any]) -> None:
        self.chunk = validate_group("policy", ScriptedOptions, config).chunk
        self.plan: list[np.ndarray] = []
        self.step = 0

    def reset(self, ctx: EpisodeContext) -> None:
        env = ctx.env
        if env is None or "base" not in env.move_groups:
            raise ValueError("scripted nav expert needs privileged simulator access and a robot with a 'base' group")
        self.arm = env.robot.targets(env.data, "arm")
        self.gripper = env.robot.targets(env.data, "gripper")
        if not isinstance(env.spec.task, NavToObjTaskSpec):
            raise ValueError(f"scripted nav expert: a nav_to_obj episode's task, not {type(env.spec.task).__name__}")
        names = [n for n in candidate_names(env.spec.task, env.scene_metadata.get("objects", {}))
                 if n in {env.model.body(b).name for b in range(env.model.nbody)}]
        if not names:
            raise ValueError("scripted nav expert: no target candidate is in the scene")
        targets = np.array([env.data.xpos[env.body_id(n)][:2] for n in names])
        start = env.robot.qpos(env.data, "base")
        grid = self._grid(env, targets, start[:2])
        free = free_space(grid, footprint_radius(env) + MARGIN)
        xs, ys = grid.centres()
        goals = np.zeros_like(free)
        for t in targets:
            r = np.hypot(xs - t[0], ys - t[1])
            ring = free & (r >= GOAL_DISTANCE[0]) & (r <= GOAL_DISTANCE[1])
            for i, j in zip(*np.nonzero(ring), strict=True):
                goals[i, j] = grid.sees(grid.centre(i, j), t)
        dist = path_lengths(free, goals, grid.res)
        cell = self._start_cell(grid, free, dist, start[:2])
        path = [grid.centre(i, j) for i, j in descend(dist, cell)] if cell is not None else []
        if not path:
            raise RuntimeError(f"scripted nav expert: no path from {start[:2].round(2).tolist()} to a goal near "
                               f"{names}")
        points = np.vstack([start[:2], *path])
        goal = targets[int(np.argmin(np.linalg.norm(targets - points[-1], axis=1)))]
        self.plan = self._trajectory(points, goal, float(start[2]), ctx.policy_dt_s)
        self.step = 0

    @staticmethod
    def _grid(env: Any, targets: np.ndarray, start: np.ndarray) -> Grid:
        boxes = geom_boxes(env.model, env.data, env.robot.body_ids)
        pts = np.vstack([*(b[[0, 1]] for b in boxes), *(b[[3, 4]] for b in boxes), targets, start[None]])
        lo, hi = pts.min(axis=0) - 0.5, pts.max(axis=0) + 0.5
        return occupancy(env.model, env.data, (lo[0], lo[1], hi[0], hi[1]), env.robot.body_ids)

    @staticmethod
    def _start_cell(grid: Grid, free: np.ndarray, dist: np.ndarray, xy: np.ndarray) -> tuple[int, int] | None:
        """The base's cell, or the nearest cell that reaches a goal when the inflation covers it."""
        cell = grid.cell(xy)
        if np.isfinite(dist[cell]):
            return cell
        xs, ys = grid.centres()
        ok = np.isfinite(dist)
        if not ok.any():
            return None
        gap = np.where(ok, np.hypot(xs - xy[0], ys - xy[1]), np.inf)
        k = np.unravel_index(int(np.argmin(gap)), gap.shape)
        return (int(k[0]), int(k[1])) if gap[k] < 0.5 else None

    def _trajectory(self, points: np.ndarray, goal: np.ndarray, yaw0: float, dt: float) -> list[np.ndarray]:
        """Base targets ``[x, y, yaw]`` per policy step: along ``points`` at SPEED, turning towards ``goal``."""
        seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        out, s, yaw = [], 0.0, yaw0
        while True:
            s = min(s + SPEED * dt, cum[-1])
            k = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
            frac = (s - cum[k]) / seg[k] if seg[k] > 0 else 1.0
            xy = points[k] + (points[k + 1] - points[k]) * frac
            want = math.atan2(goal[1] - xy[1], goal[0] - xy[0])
            turn = (want - yaw + math.pi) % (2 * math.pi) - math.pi
            yaw += float(np.clip(turn, -TURN_RATE * dt, TURN_RATE * dt))
            out.append(np.array([xy[0], xy[1], yaw]))
            if s >= cum[-1] and abs(turn) < 1e-3:
                return out

    def act(self, obs: Observation) -> Action:
        steps = [self.plan[min(self.step + k, len(self.plan) - 1)] for k in range(self.chunk)]
        self.step += self.chunk
        n = len(steps)
        return {"base": np.array(steps), "arm": np.repeat(self.arm[None], n, axis=0),
                "gripper": np.repeat(self.gripper[None], n, axis=0)}


@hookimpl
def molmo_experts() -> list[PolicyType]:
    return [PolicyType(name="nav_to_obj", factory=ScriptedNav,
                       description="occupancy grid + shortest path, drive the base, face the object")]
