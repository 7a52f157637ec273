"""Fixtures for the simulation tests: small generated pick episodes and a run context (default config)."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(scope="session")
def run():
    from molmo_lerobot.context import RunContext

    return RunContext.build()


@pytest.fixture(scope="session")
def pick_episodes():
    from molmo_lerobot.benchmark.generate import generate_benchmark

    return generate_benchmark("pick", 2, 2, 0, "test")[0]


@pytest.fixture
def pick_spec(pick_episodes, run):
    from molmo_lerobot.benchmark.task_specs import parse_episode

    return parse_episode(pick_episodes[0], run.plugins)
