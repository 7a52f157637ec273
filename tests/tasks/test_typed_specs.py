"""A task type sees its episodes' task as its own spec model (``TaskType[SpecT].task_spec``), defaults included."""

from __future__ import annotations

import copy

import pytest

from molmo_lerobot.benchmark.schema import BaseTaskSpec, EpisodeSpec, GenericTaskSpec
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.tabletop.generate import generate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing
from molmo_lerobot.tasks.pick import PickTaskSpec, PickTaskType


@pytest.fixture(scope="module")
def raw_episode() -> dict:
    return generate_benchmark("pick", 1, 1, 3, "test")[0][0]


def test_every_builtin_task_type_has_its_own_spec_model():
    plugins = RunContext.build().plugins
    for name in plugins.names("task"):
        model = plugins.task_type(name).spec_model
        assert issubclass(model, BaseTaskSpec) and model is not GenericTaskSpec, name


@pytest.mark.parametrize(("given", "expected"), [(0.05, 0.05), (None, 0.01)])
def test_a_pick_task_reads_its_typed_spec(raw_episode, given, expected):
    """An episode parsed without plugins (a GenericTaskSpec) is validated with the task's model: the
    field as given, else the model's default, never a second default kept by the task."""
    raw = copy.deepcopy(raw_episode)
    raw["task"].pop("succ_pos_threshold", None)
    if given is not None:
        raw["task"]["succ_pos_threshold"] = given
    generic = EpisodeSpec.model_validate(raw)
    assert type(generic.task) is GenericTaskSpec
    tt = PickTaskType()
    typed = tt.task_spec(generic)
    assert type(typed) is PickTaskSpec and typed.succ_pos_threshold == expected
    assert tt.thresholds(generic) == {"succ_pos_threshold": expected}
    run = RunContext.build()
    env = build_env(parse_episode(raw, run.plugins), Timing(), run)
    try:
        task = tt.create(generic, env)
        assert isinstance(task.spec, PickTaskSpec) and task.threshold == expected
    finally:
        env.close()


def test_a_parsed_episode_keeps_its_spec_instance(raw_episode):
    spec = parse_episode(raw_episode, RunContext.build().plugins)
    assert PickTaskType().task_spec(spec) is spec.task
