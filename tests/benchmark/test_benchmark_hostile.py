"""Hostile and careless benchmark files: duplicates, ambiguous layouts, deep JSON, FIFOs, unbounded values."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys

import pytest

from molmo_lerobot.benchmark.load import MAX_JSON_DEPTH, BenchmarkError, load_benchmark
from molmo_lerobot.cli.bench import main
from molmo_lerobot.plugins import Plugins

#: the installed plugins, whose spec models type each episode's task
PLUGINS = Plugins()


def _problems(path) -> list[str]:
    with pytest.raises(BenchmarkError) as info:
        load_benchmark(path, PLUGINS)
    return [str(p) for p in info.value.problems]


@pytest.fixture
def episodes(data):
    return json.loads((data / "pick_list" / "benchmark.json").read_text())


def _write(tmp_path, episodes, name="b"):
    d = tmp_path / name
    d.mkdir()
    (d / "benchmark.json").write_text(json.dumps(episodes))
    return d


def test_duplicate_episodes_are_refused_by_content(episodes, tmp_path):
    dup = copy.deepcopy(episodes[1])
    dup = json.loads(json.dumps(dup, sort_keys=True))  # same content, other key order
    d = _write(tmp_path, [*episodes, dup])
    assert _problems(d) == [f"{d / 'benchmark.json'}: episode 4: duplicate of episode 1 "
                            "(same content: the same trial would count twice)"]


def test_a_directory_with_both_layouts_is_ambiguous(data, tmp_path):
    import shutil

    d = tmp_path / "both"
    shutil.copytree(data / "pick_legacy", d)
    shutil.copy(data / "pick_list" / "benchmark.json", d / "benchmark.json")
    (problem,) = _problems(d)
    assert problem.startswith(f"{d}: ambiguous layout") and "benchmark.json" in problem


@pytest.mark.parametrize("depth", [MAX_JSON_DEPTH + 1, 100_000])
def test_deeply_nested_json_is_one_line(episodes, tmp_path, depth, capsys):
    ep = copy.deepcopy(episodes[0])
    d = tmp_path / "deep"
    d.mkdir()
    text = json.dumps([ep])[:-2] + ', "junk": ' + "[" * depth + "]" * depth + "}]"
    (d / "benchmark.json").write_text(text)
    assert _problems(d) == [f"{d / 'benchmark.json'}: JSON nested deeper than {MAX_JSON_DEPTH} levels"]
    assert main(["validate", str(d)]) == 2
    err = capsys.readouterr().err
    assert "nested deeper" in err and "Traceback" not in err and "RecursionError" not in err


def test_a_fifo_episode_file_does_not_hang_validate(data, tmp_path):
    import shutil

    d = tmp_path / "fifo"
    shutil.copytree(data / "pick_legacy", d)
    fifo = d / "house_12" / "episode_00000000.json"
    fifo.unlink()
    os.mkfifo(fifo)
    proc = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.bench", "validate", str(d), "--schema-only"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert f"{fifo}: cannot read: not a regular file" in proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    ("edit", "field", "message"),
    [
        (lambda e: e.update(house_index=True), "house_index", "Input should be a valid integer (got true)"),
        (lambda e: e.update(img_resolution=[100000, 100000]), "img_resolution",
         "width and height must be in 1..8192"),
        (lambda e: e["task"].update(task_horizon_sec=1e12), "task.task_horizon_sec",
         "Input should be less than or equal to 3600"),
    ],
)
def test_unbounded_and_coerced_values_are_refused(episodes, tmp_path, edit, field, message):
    bad = copy.deepcopy(episodes)
    edit(bad[2])
    d = _write(tmp_path, bad)
    (problem,) = _problems(d)
    assert problem.startswith(f"{d / 'benchmark.json'}: episode 2: field {field}: {message}")


def test_generate_name_cannot_leave_benchmarks(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["generate", "--houses", "1", "--episodes-per-house", "1", "--name", "../../escape"]) == 2
    assert "--name '../../escape' names the output directory" in capsys.readouterr().err
    assert not (tmp_path.parent.parent / "escape").exists()
