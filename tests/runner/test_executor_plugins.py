"""Executors are a plugin kind: ``executor=<name>`` resolves through ``molmo_executors``, its options
are checked against the executor's model before any output, and a plugin's executor runs the episodes."""

from __future__ import annotations

import json
from typing import ClassVar

import pytest

from molmo_lerobot import hookimpl
from molmo_lerobot.config import compose
from molmo_lerobot.errors import RunError
from molmo_lerobot.executor_types import ExecutorOptions, ExecutorType
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.builtin_executors import LOCAL
from molmo_lerobot.runner.evaluate import _make_executor, run_evaluation
from molmo_lerobot.runner.local import LocalExecutor


class CountingOptions(ExecutorOptions):
    label: str = "plain"
    slots: int = 1


class CountingExecutor(LocalExecutor):
    """The local pool, counting the plans it is given."""

    made: ClassVar[list[tuple[int, CountingOptions]]] = []
    ran: ClassVar[list[int]] = []

    def run(self, job, items, on_result, on_startup=None):
        CountingExecutor.ran.extend(item.episode_index for item in items)
        super().run(job, items, on_result, on_startup)


def _counting(workers, options, timeout_s, retries, fork_servers):
    CountingExecutor.made.append((workers, options))
    return CountingExecutor(options.slots, fork_servers=fork_servers, timeout_s=timeout_s, retries=retries)


class CountingPlugin:
    @hookimpl
    def molmo_executors(self):
        return [ExecutorType("counting", CountingOptions, _counting, "the local pool, counted")]


@pytest.fixture
def counting():
    CountingExecutor.made.clear()
    CountingExecutor.ran.clear()
    plugins = Plugins()
    plugins.add(CountingPlugin(), "counting")
    return plugins


def _config(tmp_path, **executor) -> RunConfig:
    base = compose(["policy=random", "workers=1", "limit=2", "horizon=2", f"output_dir={tmp_path / 'run'}",
                    "progress=false"])
    return RunConfig.of({**RunConfig.of(base).plain(), "executor": executor})


def test_the_built_in_executors_are_plugins():
    plugins = Plugins()
    assert {"local", "ray"} <= set(plugins.names("executor"))
    assert plugins.provider("executor", "local").name == "core_config"
    assert LOCAL.defaults() == {"name": "local", "start_method": "forkserver", "egl_devices": None,
                                "cuda_devices": None}


def test_a_plugin_executor_is_resolved_and_its_options_validated(counting, tmp_path):
    ex = _make_executor(_config(tmp_path, name="counting", label="x", slots=2), counting)
    assert isinstance(ex, CountingExecutor) and ex.workers == 2
    assert CountingExecutor.made == [(1, CountingOptions(name="counting", label="x", slots=2))]
    with pytest.raises(RunError) as info:
        _make_executor(_config(tmp_path, name="counting", slots="two", lable="y"), counting)
    assert str(info.value).splitlines() == [
        "executor.slots: input should be a valid integer, got 'two'",
        "executor.lable: executor counting has no such option (options: label, slots)"]


def test_an_unknown_executor_is_the_registry_error_with_close_matches(counting, tmp_path):
    with pytest.raises(RunError, match=r"^unknown executor 'countin'; did you mean 'counting'\? "
                                       r"\(available: counting, local, ray\)"):
        _make_executor(_config(tmp_path, name="countin"), counting)


def test_a_plugin_executor_runs_the_episodes(tmp_path, in_process_plugins, fork_servers):
    CountingExecutor.made.clear()
    CountingExecutor.ran.clear()
    in_process_plugins(CountingPlugin(), "counting")
    result = run_evaluation(_config(tmp_path, name="counting", label="run"), fork_servers)
    assert CountingExecutor.ran == [0, 1] and CountingExecutor.made[0][1].label == "run"
    assert result.summary["executor"] == "counting" and result.summary["n_episodes"] == 2
    assert json.loads((tmp_path / "run" / "results.json").read_text())["n_episodes"] == 2


def test_bad_options_of_a_plugin_executor_stop_the_run_before_any_output(tmp_path, in_process_plugins):
    in_process_plugins(CountingPlugin(), "counting")
    with pytest.raises(RunError, match=r"^executor.slots: input should be a valid integer, got 'many'$"):
        run_evaluation(_config(tmp_path, name="counting", slots="many"))
    assert not (tmp_path / "run").exists()
