"""Run options are checked up front: one line per problem, exit status 2, nothing written."""

from __future__ import annotations

import pytest

from eval_runs import refusal
from molmo_lerobot.cli.eval import exit_status
from molmo_lerobot.run_config import MAX_PHYSICS_STEPS, config_problems, episode_work_problem


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["limit=-1"], "limit: expected a positive integer (or null for every episode), got -1"),
        (["limit=0"], "limit: expected a positive integer (or null for every episode), got 0"),
        (["limit=abc"], "limit: expected a positive integer (or null for every episode), got 'abc'"),
        (["horizon=0"], "horizon: expected a whole number of policy steps in 1..100000 (or null), got 0"),
        (["horizon=-5"], "horizon: expected a whole number of policy steps in 1..100000 (or null), got -5"),
        (["horizon=1e99"], "horizon: expected a whole number of policy steps in 1..100000 (or null), got 1e+99"),
        (["seed=abc"], "seed: expected an integer, got 'abc'"),
        (["workers=abc"], "workers: expected a positive integer, got 'abc'"),
        (["worker_threads=0"],
         "worker_threads: expected an integer in 1..1024 (or null for the libraries' default), got 0"),
        (["timing.policy_dt_ms=0"], "timing.policy_dt_ms: expected a positive number of milliseconds, got 0"),
        (["timing.ctrl_dt_ms=abc"], "timing.ctrl_dt_ms: expected a positive number of milliseconds, got 'abc'"),
        (["timing.ctrl_dt_ms=5"], "timing: policy_dt_ms / ctrl_dt_ms must be a whole multiple"),
        (["+horizons.pick=1e12"],
         "horizons.pick: expected a positive number of seconds, got 1000000000000.0 (at most 3600)"),
        (["episode_timeout_s=-1"],
         "episode_timeout_s: expected a positive number of seconds (at most 604,800: a week), got -1"),
        (["resume=maybe"], "resume: expected true or false, got 'maybe'"),
        # bounded work per episode: the run's horizon times the physics steps per policy step
        (["horizon=100000"], "horizon: 100,000 policy steps x 33 physics steps each = 3,300,000 physics steps"),
        # every pick episode's default horizon (15 s) at a 0.1 us physics step
        (["timing.sim_dt_ms=0.0001"], "policy steps x 660,000 physics steps each"),
    ],
)
def test_nonsense_options_are_one_line_and_write_nothing(args, needle, tmp_path):
    out = tmp_path / "out"
    [line] = refusal(*args, "limit=2" if not args[0].startswith("limit") else "workers=1", f"output_dir={out}")
    assert needle in line
    assert not out.exists()


def test_every_problem_is_listed_one_per_line(tmp_path):
    lines = refusal("limit=0", "seed=x", "horizon=-1", "workers=0", f"output_dir={tmp_path / 'out'}")
    assert {ln.split(": ")[0].split(" ")[0] for ln in lines} == {"limit", "seed", "horizon", "workers"}
    assert len(lines) == 4


def test_defaults_are_valid():
    from omegaconf import OmegaConf

    from molmo_lerobot.config import compose

    assert config_problems(OmegaConf.to_container(compose([]), resolve=True)) == []


def test_episode_work_bound():
    timing = {"policy_dt_ms": 66.0, "ctrl_dt_ms": 2.0, "sim_dt_ms": 2.0}
    assert episode_work_problem(600, timing, "x") is None  # pick_and_place at 40 s
    assert episode_work_problem(MAX_PHYSICS_STEPS // 33 + 1, timing, "x") is not None


def test_hydra_composes_the_schema_defaults_and_validation_keeps_a_composed_config_as_it_is():
    from omegaconf import OmegaConf

    from molmo_lerobot.config import compose
    from molmo_lerobot.run_config import RunConfig

    composed = OmegaConf.to_container(compose([]), resolve=True)
    assert RunConfig().plain() == composed and list(RunConfig().plain()) == list(composed)
    tuned = compose(["policy=lerobot", "policy.path=x", "timing.ctrl_dt_ms=6", "+horizons.pick=15", "+trace_dir=t"])
    assert RunConfig.of(tuned).plain() == OmegaConf.to_container(tuned, resolve=True)


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["foo=1"], "Could not override 'foo': no such key (a plugin's own key is added with +foo=1)"),
        (["timing.sleeep=true"], ("Could not override 'timing.sleeep': timing has no key 'sleeep'; "
                                  "did you mean 'timing.sleep'?")),
        (["+camera.evl=true"], ("camera.evl: unknown key (known: overrides, system, eval, rand_level, "
                                "randomization)")),
        (["workers=abc"], "workers: expected a positive integer, got 'abc'"),
        (["end_on_success=yes"], "end_on_success: expected true or false, got 'yes'"),
        (["task_rules=ours"], "task_rules: expected one of molmospaces, fixed, got 'ours'"),
        (["custom_object.name=5"], "custom_object.name: input should be a valid string, got 5"),
        (["record_hold_steps=-1"], "record_hold_steps: expected a non-negative integer or null, got -1"),
    ],
)
def test_an_unknown_key_or_a_wrongly_typed_value_is_one_line_naming_the_key(args, line, tmp_path):
    assert refusal(*args, f"output_dir={tmp_path / 'out'}") == [line]
    assert not (tmp_path / "out").exists()


def test_a_plugins_own_top_level_key_is_kept():
    from molmo_lerobot.run_config import RunConfig

    run = RunConfig.of({"trace_dir": "/tmp/t", "policy": {"name": "sine", "amplitude": 0.3}})
    assert run.plain()["trace_dir"] == "/tmp/t" and run.plain()["policy"] == {"name": "sine", "amplitude": 0.3}
    assert RunConfig.of(run) is run  # validated once


def test_the_cli_is_a_public_hydra_app_that_reads_its_own_command_line():
    import inspect

    import molmo_lerobot.cli.eval as cli

    source = inspect.getsource(cli)
    assert "hydra._internal" not in source and "hydra.main(" in source
    assert inspect.signature(cli.main).parameters == {}  # in-process callers compose instead
    assert "sys.argv =" not in source  # no swapping the command line around Hydra


def test_the_exit_status_of_a_finished_run():
    scored = {"success_rate": 0.0}
    assert exit_status(scored) == 0 and exit_status({**scored, "push": {"ok": True}}) == 0
    assert exit_status({"success_rate": None}) == 1  # no episode ran: no score
    assert exit_status({**scored, "push": {"ok": False}}) == 1
