"""Fixtures for the simulation tests: small generated pick episodes and a plugin set."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(scope="session")
def plugins():
    from molmo_lerobot.plugins import get_plugins

    return get_plugins()


@pytest.fixture(scope="session")
def pick_episodes():
    from molmo_lerobot.benchmark.generate import generate_benchmark

    return generate_benchmark("pick", 2, 2, 0, "test")[0]


@pytest.fixture
def pick_spec(pick_episodes, plugins):
    from molmo_lerobot.benchmark.task_specs import parse_episode

    return parse_episode(pick_episodes[0], plugins)
