"""Contact sheet of nav_v1 (issue 27): the head and wrist cameras at the start and at the first success.

``python tests/scenes/nav_contact_sheet.py docs/contact_sheet_nav_v1.png``: one row per episode (one from
each of six houses), the scripted expert driving it; columns head / wrist at reset, then head / wrist at
the first step the task succeeds, 224² each, as the policy sees them, plus a top view of the house."""

from __future__ import annotations

import sys

import cv2
import mujoco
import numpy as np

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.scripted_nav import ScriptedNav
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing

EPISODES = (0, 11, 22, 33, 44, 55)


def _label(image: np.ndarray, text: str) -> np.ndarray:
    out = np.ascontiguousarray(image.copy())
    cv2.rectangle(out, (0, 0), (out.shape[1], 14), (0, 0, 0), -1)
    cv2.putText(out, text[:40], (2, 11), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def _top(env) -> np.ndarray:
    """A view from above the house, looking down on the robot."""
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = [*env.robot.qpos(env.data, "base")[:2], 0.0]
    cam.distance, cam.elevation, cam.azimuth = 7.0, -75.0, 90.0
    renderer = mujoco.Renderer(env.model, 224, 224)
    try:
        renderer.update_scene(env.data, camera=cam, scene_option=env.camera_view_options())
        return renderer.render()
    finally:
        renderer.close()


def _row(spec, index: int, ctx: RunContext) -> np.ndarray:
    env = build_env(spec, Timing(), ctx)
    try:
        env.reset(spec.seed)
        task = ctx.plugins.task_type(spec.task_name).create(spec, env)
        task.setup()
        start = [_label(env.render(c), f"{index} start {c}") for c in env.camera_names]
        expert = ScriptedNav({})
        expert.reset(EpisodeContext(spec=spec, episode_index=index, seed=spec.seed or 0, prompt=spec.prompt,
                                    move_groups=env.move_groups, policy_dt_s=env.timing.policy_dt_s,
                                        env=env, catalog=ctx.catalog))
        for _ in range(len(expert.plan) // expert.chunk + 4):
            chunk = expert.act({})
            for k in range(expert.chunk):
                env.step({g: chunk[g][k] for g in chunk})
                if task.success():
                    break
            else:
                continue
            break
        _, dist = task.nearest()
        end = [_label(env.render(c), f"success {task.success()} {dist:.2f} m {c}") for c in env.camera_names]
        return np.hstack([*start, *end, _label(_top(env), spec.prompt)])
    finally:
        env.close()


def main(out: str) -> None:
    ctx = RunContext.build()
    bench = load_benchmark(data_path("benchmarks") / "nav_v1", ctx.plugins)
    sheet = np.vstack([_row(bench.episodes[i], i, ctx) for i in EPISODES])
    cv2.imwrite(out, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    print(out, sheet.shape)


if __name__ == "__main__":
    main(sys.argv[1])
