"""Render profiles (issue 36): the look is part of the trial, and each camera renders once per state in one
GL context per process."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing
from molmo_lerobot.sim.render_profile import PROFILES, RenderProfile, RenderProfileError, resolve_profile

V2 = ("pick", "pick_and_place", "next_to", "color", "open", "close")


def _env(bench_name: str, profile: str | None = None, index: int = 0):
    ctx = RunContext.build()
    bench = load_benchmark(data_path("benchmarks") / bench_name, ctx.plugins)
    ctx = ctx.for_benchmark(bench)
    if profile is not None:
        ctx = RunContext(config=ctx.config, plugins=ctx.plugins, settings=ctx.settings, catalog=ctx.catalog,
                         render_record=resolve_profile(profile).record())
    env = build_env(bench.episodes[index], Timing(), ctx)
    env.reset(0)
    return env


def test_overrides_are_recorded_never_silent():
    assert resolve_profile(None, {}) == PROFILES["v2"]
    shadows = resolve_profile("v2", {"MOLMO_SCENE_SHADOWS": "0", "MOLMO_SCENE_TEXTURE_SIZE": "128"})
    assert shadows.shadows is False and shadows.texture_size == 128
    assert shadows.record()["overrides"] == {"MOLMO_SCENE_SHADOWS": "0", "MOLMO_SCENE_TEXTURE_SIZE": "128"}
    assert RenderProfile.from_record(json.loads(json.dumps(shadows.record()))) == shadows
    with pytest.raises(RenderProfileError, match="unknown profile 'v9'"):
        resolve_profile("v9", {})


def test_v2_renders_every_scene_as_built_and_v3_turns_the_costly_knobs_off(monkeypatch, tmp_path):
    """The v2 profile is the identity (the published v2 look, pixel for pixel as mujoco.Renderer draws the
    scene); v3 has no shadow-casting light, no reflections, no multisampling and dimmer lights."""
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path))
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "64")
    v2, v3 = _env("pick_v2", "v2"), _env("pick_v2", "v3")
    assert v2.model.light_castshadow.any() and (v2.model.mat_reflectance > 0).any()
    assert v2.model.vis.quality.offsamples == 4
    assert not v3.model.light_castshadow.any() and not v3.model.mat_reflectance.any()
    assert v3.model.vis.quality.offsamples == 0
    np.testing.assert_allclose(v3.model.light_diffuse, v2.model.light_diffuse * PROFILES["v3"].exposure)
    for cam in v2.camera_names:
        ref = mujoco.Renderer(v2.model, 224, 224)
        ref.update_scene(v2.data, camera=cam, scene_option=v2.camera_view_options())
        np.testing.assert_array_equal(v2.render(cam), ref.render())
        ref.enable_depth_rendering()
        np.testing.assert_allclose(v2.render_depth(cam), ref.render(), rtol=1e-6)
        ref.close()


def test_a_camera_renders_once_per_state_in_one_gl_context(monkeypatch):
    """The policy's observation, the recorder and the Gymnasium env's ``render()`` share one frame per
    camera and state; episodes share the process's GL context (each env made two before)."""
    contexts, draws = [], []
    real_gl, real_render = mujoco.gl_context.GLContext, mujoco._render.mjr_render

    def gl(*args, **kwargs):
        contexts.append(1)
        return real_gl(*args, **kwargs)

    def draw(*args):
        draws.append(1)
        return real_render(*args)

    for mod in (mujoco, mujoco.gl_context):
        monkeypatch.setattr(mod, "GLContext", gl)
    for mod in (mujoco, mujoco._render):
        monkeypatch.setattr(mod, "mjr_render", draw)
    for _ in range(2):
        env = _env("pick_v1")
        obs = env.observe(images=True)
        again = env.observe(images=True)  # the recorder's read of the same state
        exterior = env.render(env.camera_names[-1])  # gym_env.render()
        assert exterior is obs["images"][env.camera_names[-1]] is again["images"][env.camera_names[-1]]
        env.step({g: env.robot.targets(env.data, g) for g in env.move_groups})
        env.observe(images=True)
        env.close()
    assert len(draws) == 2 * 2 * len(env.camera_names)
    assert len(contexts) <= 1


def test_v3_benchmarks_are_the_v2_episodes_seen_through_v3():
    """``*_v3`` = the v2 trial's episodes (same content hash), its metadata naming profile v3; v2 names none."""
    plugins = RunContext.build().plugins
    for task in V2:
        v2 = load_benchmark(data_path("benchmarks") / f"{task}_v2", plugins)
        v3 = load_benchmark(data_path("benchmarks") / f"{task}_v3", plugins)
        assert v3.sha256 == v2.sha256 and v3.name == f"{task}_v3"
        assert v2.metadata.render_profile is None and v3.metadata.render_profile == "v3"
        mutable = ("name", "description", "render_profile")
        assert ({k: v for k, v in v3.metadata.model_dump().items() if k not in mutable}
                == {k: v for k, v in v2.metadata.model_dump().items() if k not in mutable})


def test_houses_rendered_in_turn_in_the_shared_context_look_as_alone():
    """Two compiled models share the GL context: each frame is drawn into its own model's buffers (a reset
    to another house and back gave a different exterior frame before)."""
    first = _env("pick_v1", index=3)
    frames = {cam: first.render(cam).copy() for cam in first.camera_names}
    other = _env("pick_v1", index=36)
    assert other.spec.house_index != first.spec.house_index
    [other.render(cam) for cam in other.camera_names]
    again = _env("pick_v1", index=3)
    for cam, frame in frames.items():
        np.testing.assert_array_equal(again.render(cam), frame)


def test_a_profile_changes_the_look_only(monkeypatch, tmp_path):
    """v2 and v3 of one episode step to the same state bit for bit: a policy that reads no camera (the
    scripted expert, random) scores a v3 benchmark exactly as its v2."""
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path))
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "64")
    v2, v3 = _env("pick_v2", "v2"), _env("pick_v2", "v3")
    rng = np.random.default_rng(0)
    for _ in range(5):
        action = {g: v2.robot.targets(v2.data, g) + rng.normal(0, 0.05, size=dim) for g, dim in v2.move_groups.items()}
        v2.step(action)
        v3.step(action)
    np.testing.assert_array_equal(v2.data.qpos, v3.data.qpos)
    np.testing.assert_array_equal(v2.data.qvel, v3.data.qvel)
