"""One lookup for benchmark names: the shipped benchmarks and those a plugin ships (``molmo_benchmarks``)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from molmo_lerobot import hookspecs
from molmo_lerobot.benchmark.packs import benchmark_pack
from molmo_lerobot.benchmark.registry import UnknownBenchmark, benchmark_dir, benchmark_names, find_benchmark
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import PluginConflict, Plugins


class PackPlugin:
    """A third-party benchmark pack: every benchmark directory below ``root``."""

    def __init__(self, root: Path) -> None:
        self.root = root

    @hookspecs.hookimpl
    def molmo_benchmarks(self):
        return benchmark_pack(self.root)


def _pack(tmp_path: Path, *names: str) -> Path:
    root = tmp_path / "pack"
    for name in names:
        (root / name).mkdir(parents=True)
        shutil.copy(data_path("benchmarks") / "pick_v1" / "benchmark.json", root / name / "benchmark.json")
    (root / "notes").mkdir()  # no benchmark.json: not a benchmark
    (root / "README.md").write_text("a pack\n")
    return root


def test_every_shipped_benchmark_is_registered_by_its_directory_name():
    plugins = Plugins()
    shipped = sorted(p.name for p in data_path("benchmarks").iterdir() if (p / "benchmark.json").is_file())
    assert benchmark_names(plugins) == shipped and len(shipped) == 20
    assert benchmark_dir("door_v1", plugins) == data_path("benchmarks") / "door_v1"


def test_a_plugins_pack_is_found_by_name_and_a_path_wins_over_a_name(tmp_path, monkeypatch):
    plugins = Plugins()
    plugins.add(PackPlugin(_pack(tmp_path, "mine_v1")), "my_pack")
    assert "mine_v1" in benchmark_names(plugins) and "notes" not in benchmark_names(plugins)
    assert find_benchmark("mine_v1", plugins) == tmp_path / "pack" / "mine_v1"
    (tmp_path / "pick_v1").mkdir()  # a directory of that name here is taken as the path it is
    monkeypatch.chdir(tmp_path)
    assert find_benchmark("pick_v1", plugins) == Path("pick_v1")


def test_an_unknown_name_says_what_there_is():
    with pytest.raises(UnknownBenchmark, match=r"^unknown benchmark 'pick_v9': neither a path nor a registered "
                                              r"benchmark \(close_v1, .*, pick_v3\)$"):
        find_benchmark("pick_v9", Plugins())
    with pytest.raises(UnknownBenchmark, match=r"^unknown benchmark 'pick_v9'; did you mean 'pick_v3', "
                                              r".*\(available: close_v1, "):
        benchmark_dir("pick_v9", Plugins())


def test_a_pack_shipping_a_shipped_name_clashes_until_pinned(tmp_path):
    plugins = Plugins()
    plugins.add(PackPlugin(_pack(tmp_path, "pick_v1")), "impostor")
    with pytest.raises(PluginConflict, match=r"benchmark 'pick_v1' is provided by plugin 'core_config'.* and "
                                             r"plugin 'impostor'.*plugins.prefer.benchmark.pick_v1="):
        benchmark_dir("pick_v1", plugins)
    plugins.set_preferences({"benchmark": {"pick_v1": "impostor"}})
    assert benchmark_dir("pick_v1", plugins) == tmp_path / "pack" / "pick_v1"
