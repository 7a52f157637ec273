"""Rendering (issue 17 item 3): each camera is rendered once per observation even when both the
policy and a recorder want images (runs by default), and the per-frame render cost at the
resolutions in use (224², MolmoSpaces' 624x352 and 640x368), with and without shadows (perf:
``pytest -m perf -s tests/perf/test_render_cost.py``; figures printed, nothing asserted)."""

from __future__ import annotations

import statistics
import time

import mujoco
import numpy as np
import pytest

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.policies.base import Policy
from molmo_lerobot.recording import Recorder
from molmo_lerobot.runner.episode import EpisodeSession
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.plan import plan_spec
from molmo_lerobot.runner.rollout import rollout
from molmo_lerobot.sim.env import Timing

CHUNK = 4


def episode(resolution=None):
    run = RunContext.build()
    spec = load_benchmark(data_path("benchmarks") / "pick_v1", run.plugins).episodes[0]
    if resolution is not None:
        spec = spec.model_copy(update={"img_resolution": resolution})
    env = build_env(spec, Timing(), run)
    env.reset(0)
    return spec, env, run


class ImagePolicy(Policy):
    """Wants images; holds the arm; keeps every observation it was given."""

    def __init__(self) -> None:
        self.seen: list[dict] = []

    def reset(self, ctx) -> None:
        self.seen.clear()

    def act(self, obs):
        self.seen.append(obs)
        return {"arm": np.repeat(np.asarray(obs["qpos"]["arm"])[None], CHUNK, 0), "gripper": np.zeros((CHUNK, 1))}


class FrameRecorder(Recorder):
    def __init__(self) -> None:
        self.frames: list[dict] = []

    def start_episode(self, info) -> None:
        pass

    def record_step(self, obs, action, reward, success, done) -> None:
        self.frames.append(obs)

    def end_episode(self, result) -> None:
        pass


def test_each_camera_is_rendered_once_per_observation(monkeypatch):
    spec, env, run = episode()
    renders: list[str] = []
    original = env.render
    monkeypatch.setattr(env, "render", lambda cam: renders.append(cam) or original(cam))
    task = run.plugins.task_type(spec.task_name).create(spec, env)
    policy, recorder, horizon = ImagePolicy(), FrameRecorder(), 10
    session = EpisodeSession.start(plan_spec(spec, run.plugins, seed=0, horizon=horizon), spec, env, task, run,
                                   policy=policy)
    rollout(session, policy, [recorder], "image_policy")
    env.close()
    assert len(recorder.frames) == horizon and len(policy.seen) == -(-horizon // CHUNK)
    assert renders == list(env.camera_names) * horizon  # one render per camera per observation
    # the policy got the very frames the recorder got, not renders of its own
    for k, obs in enumerate(policy.seen):
        assert obs is recorder.frames[k * CHUNK]


def test_policy_without_images_and_no_recorder_renders_nothing(monkeypatch):
    spec, env, run = episode()
    monkeypatch.setattr(env, "render", lambda cam: pytest.fail("rendered without a consumer"))
    policy = ImagePolicy()
    policy.needs_images = False
    task = run.plugins.task_type(spec.task_name).create(spec, env)
    session = EpisodeSession.start(plan_spec(spec, run.plugins, seed=0, horizon=5), spec, env, task, run, policy=policy)
    rollout(session, policy, [], "image_policy")
    env.close()


@pytest.mark.perf
def test_render_cost_per_frame():
    frames = 30
    rows = []
    for width, height in ((224, 224), (624, 352), (640, 368)):
        _, env, _ = episode([width, height])
        renderer = mujoco.Renderer(env.model, height=height, width=width)
        for shadows in (True, False):
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
            times = []
            for i in range(frames + 3):
                cam = env.camera_names[i % len(env.camera_names)]
                t0 = time.perf_counter()
                renderer.update_scene(env.data, camera=cam)
                renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
                renderer.render()
                if i >= 3:  # warm-up
                    times.append(1000 * (time.perf_counter() - t0))
            rows.append((f"{width}x{height}", shadows, statistics.median(times)))
        renderer.close()
        env.close()
    print(f"\nper-frame render cost (update_scene + render, one camera, median of {frames}):")
    for res, shadows, ms in rows:
        print(f"  {res:>8}  shadows={'on ' if shadows else 'off'}  {ms:7.2f} ms")
