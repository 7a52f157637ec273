"""Scene cost v2 / v1 (issue 26 item 5), from one run: scene build time (assemble + compile, model cache
cleared) and render time per 224² frame (every camera of the episode, after a warm-up render) for the
first episodes of pick_v1 (procedural tabletop, Panda, standard cameras) and pick_v2 (libero_rooms,
franka_droid, DROID cameras) at the default texture size and shadows, then for v2 with shadows off and
128 px textures (``pytest -m perf -s tests/perf/test_scene_cost_v2.py``; figures printed, nothing asserted)."""

from __future__ import annotations

import statistics
import time

import pytest

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim import env as sim_env
from molmo_lerobot.sim.env import Timing

EPISODES = 3
RENDERS = 10


def _cost(name: str, ctx: RunContext) -> tuple[float, float]:
    builds, frames = [], []
    for spec in load_benchmark(data_path("benchmarks") / name, ctx.plugins).episodes[:EPISODES]:
        sim_env._MODEL_CACHE.clear()
        t = time.perf_counter()
        env = build_env(spec, Timing(), ctx)
        builds.append(time.perf_counter() - t)
        env.reset(0)
        for cam in env.camera_names:
            env.render(cam)  # warm-up: context, textures uploaded
            t = time.perf_counter()
            for _ in range(RENDERS):
                env.render(cam)
            frames.append((time.perf_counter() - t) / RENDERS)
        env.close()
    return statistics.median(builds), statistics.median(frames)


@pytest.mark.perf
def test_scene_cost_v2_over_v1(monkeypatch):
    ctx = RunContext.build()
    v1_build, v1_frame = _cost("pick_v1", ctx)
    rows = [("pick_v1", v1_build, v1_frame)]
    for label, env in (("pick_v2", {}), ("pick_v2 no shadows, 128 px textures",
                                         {"MOLMO_SCENE_SHADOWS": "0", "MOLMO_SCENE_TEXTURE_SIZE": "128"})):
        with monkeypatch.context() as m:
            for k, v in env.items():
                m.setenv(k, v)
            rows.append((label, *_cost("pick_v2", ctx)))
    print(f"\n{'scene':40s} {'build s':>8s} {'frame ms':>9s} {'build x v1':>11s} {'frame x v1':>11s}")
    for label, build, frame in rows:
        print(f"{label:40s} {build:8.2f} {frame * 1000:9.1f} {build / v1_build:11.1f} {frame / v1_frame:11.1f}")
