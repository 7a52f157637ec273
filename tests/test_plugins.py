"""A broken third-party plugin is reported, never fatal; asking for it names it and its error."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.benchmark.validate import validate_benchmark
from molmo_lerobot.cli.plugins import format_table
from molmo_lerobot.plugins import ENTRY_POINT_GROUP, PluginError, Plugins

DATA = Path(__file__).resolve().parent / "data" / "molmospaces"


@pytest.fixture
def broken_dist(tmp_path: Path) -> Path:
    """A distribution ``brokenbots`` with a plugin that fails to import, one whose hook raises, one that works."""
    info = tmp_path / "brokenbots-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: brokenbots\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\nur5 = brokenbots_ur5\nkuka = brokenbots_kuka\ngoodbot = brokenbots_good\n")
    (tmp_path / "brokenbots_ur5.py").write_text('raise RuntimeError("ur5 driver missing")\n')
    (tmp_path / "brokenbots_kuka.py").write_text(textwrap.dedent("""
        from molmo_lerobot import hookspecs

        @hookspecs.hookimpl
        def molmo_robots():
            raise RuntimeError("kuka meshes not found")
    """))
    (tmp_path / "brokenbots_good.py").write_text(textwrap.dedent("""
        from types import SimpleNamespace
        from molmo_lerobot import hookspecs

        @hookspecs.hookimpl
        def molmo_robots():
            return [SimpleNamespace(name="goodbot", aliases=("gb",), move_groups={"arm": 6})]
    """))
    return tmp_path


def _with_broken(broken_dist: Path, monkeypatch) -> Plugins:
    """The installed plugins plus ``brokenbots``, found on ``sys.path`` like any installed distribution."""
    monkeypatch.syspath_prepend(str(broken_dist))
    plugins = Plugins()
    assert {"ur5", "kuka", "goodbot"} <= {r.name for r in plugins.records}
    return plugins


def test_broken_plugins_are_recorded_and_the_rest_works(broken_dist, monkeypatch):
    plugins = _with_broken(broken_dist, monkeypatch)
    rec = {r.name: r for r in plugins.records}
    assert (rec["ur5"].status, rec["ur5"].error) == ("error", "RuntimeError: ur5 driver missing")
    assert rec["ur5"].distribution == "brokenbots" and rec["ur5"].version == "0.1"
    assert plugins.robot("gb").name == "goodbot"
    assert plugins.robot("franka_droid").name == "franka_droid"  # built-ins unaffected (Robotiq, never the Panda)
    assert rec["kuka"].status == "error" and "molmo_robots() failed: RuntimeError: kuka meshes not found" in rec["kuka"].error


@pytest.mark.parametrize(
    ("name", "needle"),
    [
        ("ur5", "plugin 'ur5' from brokenbots failed to load: RuntimeError: ur5 driver missing"),
        ("kuka", "plugin 'kuka' from brokenbots failed to load: molmo_robots() failed: RuntimeError: kuka meshes not found"),
    ],
)
def test_asking_for_the_broken_plugin_names_it(broken_dist, monkeypatch, name, needle):
    plugins = _with_broken(broken_dist, monkeypatch)
    with pytest.raises(PluginError) as info:
        plugins.robot(name)
    assert str(info.value).startswith(f"unknown robot {name!r}") and needle in str(info.value)


def test_validation_is_unaffected_by_broken_plugins(broken_dist, monkeypatch):
    bench = load_benchmark(DATA / "pick_list")
    clean = [str(p) for p in validate_benchmark(bench, Plugins())]
    assert [str(p) for p in validate_benchmark(bench, _with_broken(broken_dist, monkeypatch))] == clean == []


def test_validation_names_the_broken_plugin_a_benchmark_needs(broken_dist, monkeypatch, tmp_path):
    import json

    episodes = json.loads((DATA / "pick_list" / "benchmark.json").read_text())
    episodes[0]["robot"]["robot_name"] = "ur5"
    d = tmp_path / "b"
    d.mkdir()
    (d / "benchmark.json").write_text(json.dumps(episodes))
    (problem,) = validate_benchmark(load_benchmark(d), _with_broken(broken_dist, monkeypatch))
    assert (problem.episode_index, problem.field) == (0, "robot.robot_name")
    assert problem.message.startswith("no robot plugin provides 'ur5'")
    assert problem.message.endswith("; plugin 'ur5' from brokenbots failed to load: RuntimeError: ur5 driver missing")


def _molmo_plugins(broken_dist: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(broken_dist), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.plugins", *args],
                          capture_output=True, text=True, env=env, timeout=300)


def test_molmo_plugins_lists_broken_plugins_and_exits_0(broken_dist):
    res = _molmo_plugins(broken_dist, "--hooks")
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stdout + res.stderr
    table = res.stdout.split("\n\n")[0].splitlines()
    rows = {line.split()[0]: line for line in table}
    assert rows["ur5"].split()[1:4] == ["-", "brokenbots", "0.1"]
    assert rows["ur5"].endswith("error: RuntimeError: ur5 driver missing")
    assert rows["kuka"].endswith("error: molmo_robots() failed: RuntimeError: kuka meshes not found")
    assert rows["goodbot"].split()[1:5] == ["robot", "brokenbots", "0.1", "ok"]
    assert rows["franka"].split()[1:2] == ["robot"] and rows["franka"].endswith("ok")
    assert "goodbot (brokenbots_good)\n  hooks:    molmo_robots\n  provides: robot:goodbot" in res.stdout
    assert "plugins failed to load" in res.stderr


def test_table_format():
    from molmo_lerobot.plugins import PluginRecord

    table = format_table([PluginRecord("a", "m", "dist", "1.0", kinds=["robot", "task"]),
                          PluginRecord("bb", "n", "d", "2", status="error", error="ImportError: no")])
    assert table.splitlines() == [
        "NAME  KIND        DISTRIBUTION  VERSION  STATUS",
        "a     robot,task  dist          1.0      ok",
        "bb    -           d             2        error: ImportError: no",
    ]
    assert format_table([]).startswith("no plugins installed")

