"""Fixtures for the benchmark tests: the MolmoSpaces-format data and an in-process plugin set."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from molmo_lerobot import hookspecs
from molmo_lerobot.benchmark.molmospaces import task_aliases
from molmo_lerobot.plugins import Plugins

DATA = Path(__file__).resolve().parents[1] / "data" / "molmospaces"


class FakeProviders:
    """A plugin providing a pick task, a Franka (MolmoSpaces aliases) and the tabletop scenes."""

    @hookspecs.hookimpl
    def molmo_task_types(self):
        return [SimpleNamespace(name="pick", aliases=("molmo_lerobot.tasks.pick.PickTask", *task_aliases("pick")))]

    @hookspecs.hookimpl
    def molmo_robots(self):
        return [SimpleNamespace(name="franka", aliases=("franka_droid", "franka_cap"),
                                move_groups={"arm": 7, "gripper": 1})]

    @hookspecs.hookimpl
    def molmo_scene_datasets(self):
        return [SimpleNamespace(name="procedural_tabletop", aliases=())]


@pytest.fixture
def data() -> Path:
    return DATA


@pytest.fixture
def fake_plugins() -> Plugins:
    plugins = Plugins(entry_points=[])
    plugins.add(FakeProviders(), name="fake")
    return plugins
