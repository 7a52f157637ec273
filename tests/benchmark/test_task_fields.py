"""Door and nav episodes: fields of the wrong type or count, a task_type contradicting task_cls and a nav
target not in its house are refused when the benchmark is loaded or validated, naming the field."""

from __future__ import annotations

import json
import shutil

import pytest

from molmo_lerobot.benchmark.load import BenchmarkError, load_benchmark
from molmo_lerobot.benchmark.validate import validate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins


def _edited(name: str, tmp_path, **task_update):
    """The shipped benchmark ``name``'s first episode with ``task_update``, as a benchmark of its own."""
    src = data_path("benchmarks") / name
    out = tmp_path / name
    shutil.copytree(src, out)
    data = json.loads((src / "benchmark.json").read_text())
    episodes = data if isinstance(data, list) else data["episodes"]
    episodes[0]["task"].update(task_update)
    (out / "benchmark.json").write_text(json.dumps(data))
    return out


@pytest.mark.parametrize(("name", "update", "field"), [
    ("door_v1", {"articulated_joint_range": [0.0, 1.0, 2.0]}, "articulated_joint_range"),
    ("door_v1", {"articulated_joint_reset_state": []}, "articulated_joint_reset_state"),
    ("door_v1", {"door_openness_threshold": "0.5"}, "door_openness_threshold"),
    ("door_v1", {"door_body_name": ""}, "door_body_name"),
    ("nav_v1", {"succ_pos_threshold": "1.5"}, "succ_pos_threshold"),
])
def test_wrongly_typed_or_counted_fields_are_refused(name, update, field, tmp_path):
    with pytest.raises(BenchmarkError, match=field) as exc:
        load_benchmark(_edited(name, tmp_path, **update), Plugins())
    assert len(str(exc.value).splitlines()) == 1


@pytest.mark.parametrize(("name", "update", "field", "message"), [
    ("door_v1", {"task_type": "pick"}, "task.task_type",
     "'pick' contradicts task_cls 'molmo_spaces.tasks.opening_tasks.DoorOpeningTask', which is task type "
     "'door_opening'"),
    ("open_v1", {"task_type": "pick"}, "task.task_type",
     "'pick' is not a task type of task_cls 'molmo_spaces.tasks.opening_tasks.OpeningTask' (one of open, close)"),
    ("nav_v1", {"pickup_obj_name": "no_such_thing", "pickup_obj_candidates": ["no_such_thing"]},
     "task.pickup_obj_candidates", "none of ['no_such_thing'] is an object of house"),
])
def test_contradictions_and_missing_nav_targets_are_problems(name, update, field, message, tmp_path):
    plugins = Plugins()
    bench = load_benchmark(_edited(name, tmp_path, **update), plugins)
    problems = [p for p in validate_benchmark(bench, plugins, RunContext.build()) if not p.warning]
    assert [(p.episode_index, p.field) for p in problems] == [(0, field)]
    assert problems[0].message.startswith(message)


def test_odd_door_starts_are_warnings_and_listed_in_results():
    from molmo_lerobot.results import EpisodeResult, summarize

    odd = EpisodeResult(episode_index=3, house_index=0, task_cls="door_opening", success=True, success_once=True,
                        steps=2, seed=1, extra={"start_warnings": ["task.articulated_joint_reset_state: 100 ..."]})
    plain = EpisodeResult(episode_index=4, house_index=0, task_cls="door_opening", success=False,
                          success_once=False, steps=2, seed=2)
    assert summarize([odd, plain]).document()["start_warnings"] == [
        {"episode_index": 3, "warnings": ["task.articulated_joint_reset_state: 100 ..."]}]
