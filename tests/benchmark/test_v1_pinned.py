"""The published v1 trials never change: same episodes (content hash), resolved horizons and thresholds.

The numbers below are those the v1 files were published and scored with. A change to the task
types' defaults, the horizon resolution, a success rule's thresholds or the schema's canonical
form that reaches any v1 trial fails here.
"""

from __future__ import annotations

import json
from collections import Counter

import pytest

from molmo_lerobot.benchmark.load import Benchmark, load_benchmark
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.runner.plan import horizon_with_source

PLACE = {"max_place_receptacle_pos_displacement": 0.15, "max_place_receptacle_rot_displacement": 1.0472,
         "receptacle_supported_weight_frac": 0.5}
#: name -> (content sha256, {(horizon steps at 66 ms, source): episodes}, {task type: thresholds})
PINNED = {
    "pick_v1": ("3270e02ac0b75852af997e168e3b92a0df75644b66e72cd9a52c8e6a3dd953e7",
                {(303, "task_horizon_sec"): 60}, {"pick": {"succ_pos_threshold": 0.01}}),
    "pick_and_place_v1": ("1374aa0bd5caa69507baee2d5c21d0e5e70c4f08b73a6d81688df5c5f214fbc0",
                          {(606, "task_horizon_sec"): 50}, {"pick_and_place": PLACE}),
    "next_to_v1": ("f8f0cb879a9865c57cc8dc5944126425e467b9ee6568a55cd507bba0e3792bb0",
                   {(606, "task_horizon_sec"): 50},
                   {"pick_and_place_next_to": {**PLACE, "max_surface_to_surface_gap": 0.05,
                                               "min_surface_to_surface_gap": 0.0, "surface_gap_tolerance": 0.01}}),
    "color_v1": ("cc8de0de4e9955047db9016258db2fa27b913cddffd096be957344fa5ae154d4",
                 {(606, "task_horizon_sec"): 50}, {"pick_and_place_color": PLACE}),
    "open_v1": ("5029abcbe9244235cd901698bc5d854b96d3d0fa9862447e264b394baaa2e478",
                {(227, "task_horizon_sec"): 60}, {"open": {"task_success_threshold": 0.2}}),
    "close_v1": ("8afa0ef54043fb383925543f1868c2a2bfad8d4e14134a9c527a287d372110d8",
                 {(227, "task_horizon_sec"): 60}, {"close": {"task_success_threshold": 0.2}}),
    "nav_v1": ("cb3966f9c37425d3a64dedcd36edaa7af550ed91f799bdc10904eb2fc74c9523",
               {(682, "task_horizon_sec"): 60}, {"nav_to_obj": {"succ_pos_threshold": 1.5}}),
    "door_v1": ("0989b1636b3fc2a400df5865a06c6d02717a40eed5a62b081d72c170908ab5b9",
                {(606, "task_horizon_sec"): 60}, {"door_opening": {"door_openness_threshold": 0.67}}),
}


def test_every_shipped_v1_benchmark_is_pinned():
    assert sorted(p.name for p in data_path("benchmarks").iterdir() if p.name.endswith("_v1")) == sorted(PINNED)


def assert_trials(name: str, sha: str, horizons: dict, thresholds: dict) -> Benchmark:
    """The shipped benchmark ``name`` has content hash ``sha``, these resolved horizons (episodes per
    ``(steps at 66 ms, source)``) and one set of thresholds per task type; the benchmark, for more checks."""
    plugins = Plugins()
    bench = load_benchmark(data_path("benchmarks") / name, plugins)
    resolved, rules = Counter(), {}
    for spec in bench.episodes:
        task_type = plugins.task_type(spec.task_name)
        resolved[horizon_with_source(None, spec.task, task_type.default_horizon_sec, 66.0)] += 1
        rules.setdefault(task_type.name, set()).add(json.dumps(task_type.thresholds(spec), sort_keys=True))
    assert bench.sha256 == sha
    assert dict(resolved) == horizons
    assert {t: [json.loads(r) for r in rs] for t, rs in rules.items()} == {t: [r] for t, r in thresholds.items()}
    return bench


@pytest.mark.parametrize("name", sorted(PINNED))
def test_v1_trials_are_unchanged(name):
    assert_trials(name, *PINNED[name])
