"""Scene set-ups the success-rule tests share: a task's environment, holding still, and an
object dropped into its receptacle."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, BUILTIN_RECEPTACLES
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.context import RunContext
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing


def make_task_env(raw: dict):
    """The reset environment of episode ``raw`` and its task, set up."""
    run = RunContext.build()
    plugins = run.plugins
    spec = parse_episode(raw, plugins)
    env = build_env(spec, Timing(), run)
    env.reset(0)
    task = plugins.task_type(spec.task_name).create(spec, env)
    task.setup()
    return env, task


def hold(env) -> dict:
    """An action that keeps the arm where it is commanded, gripper open."""
    return {"arm": env.robot.targets(env.data, "arm"), "gripper": np.zeros(1)}


def settle(env, steps: int = 8) -> None:
    for _ in range(steps):
        env.step(hold(env))


def put_in_receptacle(env, task) -> None:
    """Drop the object upright (a capsule lying) into the middle of the receptacle and let it settle."""
    rec = env.body_pose(task.receptacle_name)
    base_top = rec[2] - BUILTIN_RECEPTACLES[task.receptacle_name].half_extents[2] + 0.008
    obj = BUILTIN_OBJECTS[task.object_name]
    lying = obj.shape == "capsule"
    quat = [math.cos(math.pi / 4), 0, math.sin(math.pi / 4), 0] if lying else [1, 0, 0, 0]
    height = obj.half_extents[0] if lying else obj.half_extents[2]
    env._place(task.object_name, np.array([rec[0], rec[1], base_top + height + 0.002, *quat]))
    mujoco.mj_forward(env.model, env.data)
    settle(env)
