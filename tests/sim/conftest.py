"""Fixtures for the simulation tests: small generated pick episodes and the env of one raw episode."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(scope="session")
def pick_episodes():
    from molmo_lerobot.content.tabletop.generate import generate_benchmark

    return generate_benchmark("pick", 2, 2, 0, "test")[0]


@pytest.fixture
def pick_spec(pick_episodes, run):
    from molmo_lerobot.benchmark.task_specs import parse_episode

    return parse_episode(pick_episodes[0], run.plugins)


@pytest.fixture
def episode_env(run):
    """``episode_env(raw, camera=None, run=None)``: the env of one raw benchmark episode under ``run`` (default:
    the session's), with the run's ``camera`` options, reset with seed 0; closed when the test ends."""
    from molmo_lerobot.benchmark.task_specs import parse_episode
    from molmo_lerobot.runner.episode_env import build_env
    from molmo_lerobot.sim.env import Timing

    envs = []

    def make(raw: dict, camera: dict | None = None, run=run):
        env = build_env(parse_episode(raw, run.plugins), Timing(), run, camera or {})
        env.reset(0)
        envs.append(env)
        return env

    yield make
    for env in envs:
        env.close()
