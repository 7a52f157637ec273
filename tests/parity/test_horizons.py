"""Horizon resolution against MolmoSpaces' ``determine_task_horizon`` (evaluation/eval_main.py).

Where theirs resolves a horizon, ours gives every episode that many steps. Two deliberate
differences (README "Timing", docs/parity.md): an episode without ``task_horizon_sec`` and no
override is an error there and runs the task type's default here (with a warning naming the file,
``horizon_source: default``); episodes with different ``task_horizon_sec`` are an error there and
each keeps its own here.
"""

from __future__ import annotations

import json

import pytest

from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.plan import horizon_with_source

pytestmark = pytest.mark.parity

V1 = ("pick_v1", "pick_and_place_v1", "next_to_v1", "color_v1", "open_v1", "close_v1")


def _task(kind: str, sec: float | None) -> dict:
    task = {"task_type": kind, "robot_base_pose": [0, 0, 0, 1, 0, 0, 0]}
    if sec is not None:
        task["task_horizon_sec"] = sec
    return task


def _cases() -> list[dict]:
    cases = [
        {"tasks": [_task("pick", 20.0)] * 3, "override": None, "policy_dt_ms": 66.0},
        {"tasks": [_task("open", 15.0)] * 2, "override": None, "policy_dt_ms": 66.0},
        {"tasks": [_task("pick_and_place", 40.0)], "override": None, "policy_dt_ms": 50.0},
        {"tasks": [_task("close", 0.99)], "override": None, "policy_dt_ms": 66.0},  # round() at .5: 15
        {"tasks": [_task("pick", 20.0), _task("pick", None)], "override": 100, "policy_dt_ms": 66.0},
        {"tasks": [_task("pick", None)], "override": None, "policy_dt_ms": 66.0},
        {"tasks": [_task("pick", 20.0), _task("pick_and_place", 40.0)], "override": None, "policy_dt_ms": 66.0},
    ]
    for name in V1:  # the shipped files, as their runner would read them
        tasks = [e["task"] for e in json.loads((data_path("benchmarks") / name / "benchmark.json").read_text())]
        cases.append({"tasks": tasks, "override": None, "policy_dt_ms": 66.0, "benchmark": name})
    return cases


class _Task:
    def __init__(self, raw: dict) -> None:
        self.task_horizon_sec = raw.get("task_horizon_sec")


def _ours(case: dict) -> list[tuple[int, str]]:
    plugins = Plugins()
    return [horizon_with_source(case["override"], _Task(t), plugins.task_type(t["task_type"]).default_horizon_sec,
                                case["policy_dt_ms"]) for t in case["tasks"]]


def test_horizons_match_their_determine_task_horizon(theirs):
    cases = _cases()
    got = theirs.run("their_horizons:horizons", {"cases": cases})["cases"]
    table = {"agree": 0, "missing horizon (deliberate)": 0, "mixed horizons (deliberate)": 0}
    for case, their in zip(cases, got, strict=True):
        ours = _ours(case)
        if "steps" in their:
            assert {steps for steps, _ in ours} == {their["steps"]}, case
            table["agree"] += 1
        elif "missing" in their["error"]:
            assert "default" in {source for _, source in ours}, case
            table["missing horizon (deliberate)"] += 1
        else:
            assert "inconsistent task_horizon_sec" in their["error"], their
            assert len({steps for steps, _ in ours}) > 1
            table["mixed horizons (deliberate)"] += 1
    assert table == {"agree": 11, "missing horizon (deliberate)": 1, "mixed horizons (deliberate)": 1}
