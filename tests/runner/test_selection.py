"""Which episodes a run evaluates: ``limit`` (the first K), ``episodes=[…]`` and a seeded ``sample=K``
stratified by house and task; recorded in results.json, kept by resume, paired by molmo-compare."""

from __future__ import annotations

import json
from collections import Counter

import pytest

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.config import compose
from molmo_lerobot.errors import RunError
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.run_config import RunConfig, RunConfigError
from molmo_lerobot.runner.compare import compare_runs, load_run
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.runner.selection import selection_of, stratified_sample


@pytest.fixture(scope="module")
def pick_v1():
    return load_benchmark(data_path("benchmarks") / "pick_v1", Plugins())


def test_limit_takes_one_house_and_sample_spreads_over_every_house(pick_v1):
    houses = [ep.house_index for ep in pick_v1.episodes]
    assert len(set(houses)) == 10
    first, _ = selection_of(RunConfig(limit=10), pick_v1)
    assert len({houses[i] for i in first}) <= 2  # the first K are grouped by house
    chosen, record = selection_of(RunConfig(sample=10, seed=0), pick_v1)
    assert len(chosen) == 10 and {houses[i] for i in chosen} == set(houses)
    assert record == {"kind": "sample", "sample": 10, "seed": 0, "strata": "house_index, task", "episodes": chosen}
    per_house = Counter(houses[i] for i in stratified_sample(pick_v1, 25, seed=3))
    assert sorted(per_house.values()) == [2] * 5 + [3] * 5  # 25 over 10 houses: 2 or 3 each


def test_sample_is_seeded(pick_v1):
    assert stratified_sample(pick_v1, 12, seed=4) == stratified_sample(pick_v1, 12, seed=4)
    assert stratified_sample(pick_v1, 12, seed=4) != stratified_sample(pick_v1, 12, seed=5)
    assert stratified_sample(pick_v1, 500, seed=0) == list(range(60))


@pytest.mark.parametrize("overrides, line", [
    (["limit=3", "sample=3"], "limit and sample: give at most one of limit"),
    (["episodes=[1,2]", "sample=3"], "episodes and sample: give at most one of limit"),
    (["episodes=[1,1]"], "episodes: expected a non-empty list of distinct benchmark indices (>= 0), got [1, 1]"),
    (["episodes=[]"], "episodes: expected a non-empty list"),
    (["sample=0"], "sample: expected a positive number of episodes (or null), got 0"),
])
def test_bad_selections_are_one_line_each(overrides, line):
    with pytest.raises(RunConfigError) as err:
        RunConfig.of(compose(overrides))
    assert len(err.value.problems) == 1 and err.value.problems[0].startswith(line)


def test_an_index_outside_the_benchmark_is_refused_before_any_run_directory(small_bench, tmp_path, fork_servers):
    out = tmp_path / "run"
    with pytest.raises(RunError, match=r"episodes: index 8 is outside benchmark 'pick_small' \(.*8 episodes, 0..7\)"):
        run_evaluation(compose([f"benchmark.path={small_bench}", f"output_dir={out}", "episodes=[2,8]"]), fork_servers)
    assert not out.exists()


@pytest.mark.slow
def test_episodes_are_recorded_kept_by_resume_and_paired_by_compare(small_bench, tmp_path):
    common = [f"benchmark.path={small_bench}", "policy=random", "workers=1", "horizon=2", "progress=false"]
    a = tmp_path / "a"
    run_evaluation(compose([*common, f"output_dir={a}", "episodes=[6,1,4]"]))
    results = json.loads((a / "results.json").read_text())
    assert results["selection"] == {"kind": "episodes", "episodes": [1, 4, 6]}
    ran = sorted(json.loads(line)["episode_index"] for line in (a / "episodes.jsonl").read_text().splitlines())
    assert ran == [1, 4, 6]
    with pytest.raises(RunError, match="its selection differs"):
        run_evaluation(compose([*common, f"output_dir={a}", "episodes=[1,4]", "resume=true"]))
    run_evaluation(compose([*common, f"output_dir={a}", "episodes=[6,1,4]", "resume=true"]))  # the same run

    b = tmp_path / "b"
    run_evaluation(compose([*common, f"output_dir={b}", "sample=6", "policy=scripted"]))
    chosen = json.loads((b / "results.json").read_text())["selection"]["episodes"]
    report = compare_runs(load_run(a), load_run(b))
    assert report["n_shared"] == len({1, 4, 6} & set(chosen))
    assert any("selected their episodes differently (A: episodes=[1, 4, 6]; B: sample=6 seed=0)" in n
               for n in report["notes"])
