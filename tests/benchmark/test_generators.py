"""``molmo-bench generate <generator>`` covers every shipped benchmark: each is what its generator writes,
byte for byte, for the arguments its ``benchmark_metadata.json`` records (``generator``); each ``*_v3`` is
the ``*_v2`` episodes (the same ``benchmark.json``) with render profile v3 named in its metadata.

Regenerating door_v1 is cheap and runs by default; the others are slow (the v2 generators settle
every layout in MuJoCo).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from molmo_lerobot.cli.bench import main
from molmo_lerobot.content.doors.generate import GENERATOR_ID as DOOR_GENERATOR
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import Plugins

SHIPPED = data_path("benchmarks")
V3 = sorted(p.name for p in SHIPPED.iterdir() if p.name.endswith("_v3"))
GENERATED = sorted(p.name for p in SHIPPED.iterdir() if p.is_dir() and p.name not in V3)


def generate_argv(name: str) -> list[str]:
    """The ``molmo-bench generate`` arguments the metadata of the shipped benchmark ``name`` records."""
    made = json.loads((SHIPPED / name / "benchmark_metadata.json").read_text())["generator"]
    if made.get("module") == DOOR_GENERATOR:
        generator, task = "door", []
    elif made["task"] == "nav_to_obj":
        generator, task = "nav", []
    else:
        generator, task = f"v{made['version']}", ["--task", made["task"]]
    return ["generate", generator, *task, "--houses", str(made["n_houses"]), "--episodes-per-house",
            str(made["episodes_per_house"]), "--seed", str(made["seed"]), "--name", name]


def test_every_shipped_benchmark_has_a_generator_or_is_a_v2_seen_through_v3():
    plugins = Plugins()
    generators = plugins.names("generator")
    for name in GENERATED:
        argv = generate_argv(name)
        assert argv[1] in generators, name
        assert argv[2] != "--task" or argv[3] in plugins.resolve("generator", argv[1]).tasks, name
    assert {g: sum(generate_argv(n)[1] == g for n in GENERATED) for g in generators} == {
        "v1": 6, "v2": 6, "nav": 1, "door": 1}
    for name in V3:
        v2 = SHIPPED / name.replace("_v3", "_v2")
        assert (SHIPPED / name / "benchmark.json").read_bytes() == (v2 / "benchmark.json").read_bytes()
        meta, base = (json.loads((d / "benchmark_metadata.json").read_text()) for d in (SHIPPED / name, v2))
        assert meta.pop("render_profile") == "v3" and meta.pop("name") == name and base.pop("name") == v2.name
        assert meta.pop("description") == f"{base.pop('description')}; the episodes of {v2.name} seen through " \
                                          "render profile v3"
        assert meta == base


def assert_regenerates(name: str, out: Path, capsys) -> None:
    assert main([*generate_argv(name), "--out", str(out)]) == 0, capsys.readouterr().err
    for file in ("benchmark.json", "benchmark_metadata.json"):
        assert (out / file).read_bytes() == (SHIPPED / name / file).read_bytes(), f"{name}/{file}"


def test_door_v1_regenerates_byte_for_byte(tmp_path, capsys):
    assert_regenerates("door_v1", tmp_path / "door_v1", capsys)


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in GENERATED if n != "door_v1"])
def test_shipped_benchmark_regenerates_byte_for_byte(name, tmp_path, capsys):
    assert_regenerates(name, tmp_path / name, capsys)


def test_a_one_task_generator_refuses_another_task(tmp_path, capsys):
    code = main(["generate", "door", "--task", "pick", "--houses", "1", "--episodes-per-house", "1", "--name", "x",
                 "--out", str(tmp_path / "x")])
    assert code == 2
    assert "generator 'door' makes 'door_opening' episodes only, not --task 'pick'" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
