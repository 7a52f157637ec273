"""Fixtures for the benchmark tests: the MolmoSpaces-format data and an in-process plugin set."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import pytest

from molmo_lerobot import hookspecs
from molmo_lerobot.benchmark.molmospaces import task_aliases
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.robots.base import RobotType
from molmo_lerobot.sim.scenes import SceneDataset
from molmo_lerobot.tasks.base import TaskType

DATA = Path(__file__).resolve().parents[1] / "data" / "molmospaces"


class FakePick(TaskType):
    """The pick task type's names; validation only (its episodes are never run)."""

    name = "pick"
    aliases = ("molmo_lerobot.tasks.pick.PickTask", *task_aliases("pick"))
    default_horizon_sec = 20.0

    def thresholds(self, spec):
        return {}

    def create(self, spec, env):
        raise NotImplementedError("a fake task type is never run")


class FakeFranka(RobotType):
    """A Franka's names and move groups (MolmoSpaces aliases); no model."""

    name = "franka"
    aliases = ("franka_droid", "franka_cap")
    move_groups: ClassVar[dict[str, int]] = {"arm": 7, "gripper": 1}

    def spec(self):
        raise NotImplementedError("a fake robot has no model")

    def add_to(self, world, base_pose, base_size=None):
        raise NotImplementedError("a fake robot has no model")

    def bind(self, model):
        raise NotImplementedError("a fake robot has no model")


class FakeTabletop(SceneDataset):
    """The tabletop scenes' name; no houses."""

    name = "procedural_tabletop"

    def n_houses(self):
        return None

    def build(self, house_index):
        raise NotImplementedError("a fake scene dataset builds no house")

    def metadata(self, house_index):
        raise NotImplementedError("a fake scene dataset has no metadata")


class FakeProviders:
    """A plugin providing a pick task, a Franka (MolmoSpaces aliases) and the tabletop scenes."""

    @hookspecs.hookimpl
    def molmo_task_types(self):
        return [FakePick()]

    @hookspecs.hookimpl
    def molmo_robots(self):
        return [FakeFranka()]

    @hookspecs.hookimpl
    def molmo_scene_datasets(self):
        return [FakeTabletop()]


@pytest.fixture
def data() -> Path:
    return DATA


@pytest.fixture
def fake_plugins() -> Plugins:
    plugins = Plugins(entry_points=[])
    plugins.add(FakeProviders(), name="fake")
    return plugins
