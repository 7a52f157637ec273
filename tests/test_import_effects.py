"""Importing the config and the Gymnasium env changes nothing: no plugin is loaded, nothing is put in
Hydra's ConfigStore; Hydra finds our search-path plugin itself (``hydra_plugins``) and the shipped
benchmarks' Gymnasium ids are there without any plugin."""

from __future__ import annotations

import json
import subprocess
import sys

import gymnasium as gym
from hydra.core.plugins import Plugins as HydraPlugins
from hydra.plugins.search_path_plugin import SearchPathPlugin

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.packs import BenchmarkDir
from molmo_lerobot.config import compose
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import ENTRY_POINT_GROUP, Plugins
from molmo_lerobot.runner.builtin_executors import LOCAL, RAY

PROBE = f"""
import importlib.metadata as md, json, sys
loads = []
entry_points = md.entry_points
def counting(*args, **kwargs):
    if kwargs.get("group") == {ENTRY_POINT_GROUP!r}:
        loads.append(kwargs)
    return entry_points(*args, **kwargs)
md.entry_points = counting
plugins = {{ep.module for ep in md.distribution("molmo-lerobot").entry_points if ep.group == {ENTRY_POINT_GROUP!r}}}
import molmo_lerobot.config, molmo_lerobot.gym_env
import gymnasium as gym
from hydra.core.config_store import ConfigStore
print(json.dumps({{"loads": len(loads), "plugin_modules": sorted(plugins & set(sys.modules)), "plugins": len(plugins),
    "store": sorted(k for k in ConfigStore.instance().repo if k.startswith("molmo")),
    "ids": sorted(i for i in gym.registry if i.startswith("molmo_lerobot/"))}}))
"""


def test_importing_config_and_gym_env_loads_no_plugin():
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=300, check=True)
    seen = json.loads(done.stdout.splitlines()[-1])
    assert seen["loads"] == 0 and seen["plugins"] > 20 and seen["plugin_modules"] == [] and seen["store"] == []
    shipped = sorted(p.parent.name for p in data_path("benchmarks").glob("*/benchmark.json"))
    assert seen["ids"] == sorted([*(f"molmo_lerobot/{n}" for n in shipped), "molmo_lerobot/Benchmark"])
    assert "molmo_lerobot/pick_v1" in seen["ids"]


def test_hydra_discovers_the_search_path_plugin_and_it_adds_the_config_nodes():
    found = [p.__name__ for p in HydraPlugins.instance().discover(SearchPathPlugin)]
    assert "MolmoLerobotSearchPath" in found
    cfg = compose(["executor=ray", "horizons.pick=3"])  # an executor node and an open map, neither a file
    assert cfg.executor == RAY.defaults() and cfg.horizons == {"pick": 3}
    assert compose([]).executor == LOCAL.defaults()


def test_register_benchmarks_adds_a_plugins_benchmarks(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "benchmark.json").write_text("[]")

    class Shipping:
        @hookimpl
        def molmo_benchmarks(self):
            return [BenchmarkDir("plugin_bench_for_gym", tmp_path / "mine")]

    from molmo_lerobot.gym_env import register_benchmarks

    plugins = Plugins()
    plugins.add(Shipping(), "shipping")
    ids = register_benchmarks(plugins=plugins)
    assert "molmo_lerobot/plugin_bench_for_gym" in ids and "molmo_lerobot/plugin_bench_for_gym" in gym.registry
    assert gym.registry["molmo_lerobot/plugin_bench_for_gym"].kwargs == {"benchmark": "plugin_bench_for_gym"}
