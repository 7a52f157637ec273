"""Episode plans: one frozen, picklable plan per episode, the same wherever it is made."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import pickle

import pytest

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.plan import EpisodePlanner, episode_seed

TIMING = {"policy_dt_ms": 66.0, "ctrl_dt_ms": 2.0, "sim_dt_ms": 2.0}


@pytest.fixture(scope="module")
def bench():
    return load_benchmark(data_path("benchmarks") / "pick_v1", Plugins())


def test_a_plan_is_frozen_plain_data_seeded_by_its_content(bench):
    plan = EpisodePlanner(RunContext.build({"seed": 3, "timing": TIMING}), bench).plan(4)
    raw = bench.episodes[4].model_dump(mode="json")
    assert plan.spec == raw and plan.seed == episode_seed(3, raw) and plan.error is None and plan.problems == ()
    canonical = json.dumps(raw, sort_keys=True, separators=(",", ":"))
    assert plan.digest == hashlib.sha256(canonical.encode()).hexdigest()
    assert (plan.task_type, plan.horizon_source) == ("pick", "task_horizon_sec")
    assert plan.prompt == bench.episodes[4].language.task_description
    assert pickle.loads(pickle.dumps(plan)) == plan  # what a worker receives
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.seed = 0  # type: ignore[misc]
    again = EpisodePlanner(RunContext.build({"seed": 3, "timing": TIMING, "horizon": 9}), bench).plan(4)
    assert (again.seed, again.digest, again.horizon, again.horizon_source) == (plan.seed, plan.digest, 9, "cli")


class _Tag:
    @hookimpl
    def molmo_episode_overrides(self, episode, config):
        if episode.house_index % 2:
            raise ValueError("odd house")
        return episode.model_copy(update={"language": episode.language.model_copy(
            update={"task_description": config.tag})})


def test_overrides_apply_before_seeding_and_a_failing_one_is_the_plans_error(bench, in_process_plugins):
    in_process_plugins(_Tag(), "tag")
    planner = EpisodePlanner(RunContext.build({"timing": TIMING, "tag": "tagged"}), bench)
    even = next(i for i, e in enumerate(bench.episodes) if e.house_index % 2 == 0)
    odd = next(i for i, e in enumerate(bench.episodes) if e.house_index % 2)
    plan = planner.plan(even)
    assert plan.prompt == "tagged" and plan.error is None
    assert plan.seed == episode_seed(0, plan.spec) != episode_seed(0, bench.episodes[even].model_dump(mode="json"))
    failed = planner.plan(odd)
    assert failed.error == "episode override failed: ValueError: odd house"
    assert failed.seed == episode_seed(0, bench.episodes[odd].model_dump(mode="json"))  # the episode as written
    result = failed.failed(failed.error)
    assert (result.episode_index, result.task_type, result.horizon, result.error) == (
        odd, "pick", failed.horizon, "episode override failed: ValueError: odd house")


def test_an_invalid_episode_is_planned_with_its_problems(bench, tmp_path):
    episodes = json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[:2]
    episodes[1]["language"]["task_description"] = " "
    (tmp_path / "benchmark.json").write_text(json.dumps(episodes))
    plan = EpisodePlanner(RunContext.build({"timing": TIMING}), load_benchmark(tmp_path, Plugins())).plan(1)
    assert plan.problems == ("language.task_description: empty task description",)
    assert plan.error == "invalid episode: language.task_description: empty task description"
