"""The benchmark generator: deterministic, schema-valid, and the shipped pick_v1 is its output."""

from __future__ import annotations

import json
import math

import pytest

from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS
from molmo_lerobot.benchmark.output import write_benchmark
from molmo_lerobot.benchmark.schema import BenchmarkMetadata
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.tabletop.generate import generate_benchmark
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins


def test_generation_is_deterministic_and_valid():
    a = generate_benchmark("pick", 3, 2, 7, "x")
    b = generate_benchmark("pick", 3, 2, 7, "x")
    assert json.dumps(a) == json.dumps(b)
    assert a != generate_benchmark("pick", 3, 2, 8, "x")
    episodes, meta = a
    BenchmarkMetadata.model_validate(meta)
    plugins = Plugins()
    for e in episodes:
        spec = parse_episode(e, plugins)
        target = spec.task.pickup_obj_name
        assert target in spec.scene_modifications.object_poses and spec.task_relevant_objects == [target]
        obj = BUILTIN_OBJECTS[target]
        assert spec.prompt == f"pick up the {obj.color} {obj.category}"
        assert {c.type for c in spec.cameras} == {"exocentric", "robot_mounted"}
        assert len(spec.scene_modifications.object_poses) >= 4  # target + distractors


def test_objects_do_not_overlap():
    episodes, _ = generate_benchmark("pick", 4, 3, 1, "x")
    for e in episodes:
        poses = list(e["scene_modifications"]["object_poses"].values())
        for i, p in enumerate(poses):
            for q in poses[i + 1:]:
                assert math.dist(p[:2], q[:2]) > 0.05


def test_bad_arguments():
    with pytest.raises(ValueError, match="unknown task 'push'"):
        generate_benchmark("push", 1, 1, 0, "x")
    with pytest.raises(ValueError, match="at least 1"):
        generate_benchmark("pick", 0, 1, 0, "x")


def test_write_benchmark(tmp_path):
    episodes, meta = generate_benchmark("pick", 1, 2, 0, "x")
    out = write_benchmark(tmp_path / "b", episodes, meta)
    assert json.loads((out / "benchmark.json").read_text()) == episodes
    assert json.loads((out / "benchmark_metadata.json").read_text()) == meta
    assert not list(out.glob(".*tmp"))


def test_shipped_pick_v1_is_the_generator_output():
    root = data_path("benchmarks") / "pick_v1"
    meta = json.loads((root / "benchmark_metadata.json").read_text())
    shipped = json.loads((root / "benchmark.json").read_text())
    g = meta["generator"]
    episodes, regenerated = generate_benchmark(g["task"], g["n_houses"], g["episodes_per_house"], g["seed"],
                                               meta["name"])
    assert shipped == episodes and meta == regenerated
    assert len(shipped) >= 50 and len({e["house_index"] for e in shipped}) >= 10
