"""A resume takes its options from the run (``run.json``'s ``options``): the command line gives only what it
changes, and an option given that differs from the run's is refused, one line naming it and both values."""

from __future__ import annotations

import json

import pytest

from molmo_lerobot.config import compose, given_keys
from molmo_lerobot.errors import RunError
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.run_directory import RunDirectory

RUN = ["policy=random", "benchmark=libero_object", "benchmark.image_size=64", "benchmark.hard_reset=false",
       "horizon=50", "seed=3", "workers=1", "record=true"]


def _options(*overrides: str) -> dict:
    return RunConfig.of(compose(list(overrides))).plain()


def _resume(run_dir: RunDirectory, *overrides: str) -> dict:
    """The options ``molmo-eval output_dir=<run> resume=true *overrides`` runs with."""
    command = [f"output_dir={run_dir.path}", "resume=true", *overrides]
    return run_dir.resume_options(_options(*command), given_keys(command))


@pytest.fixture
def run_dir(tmp_path) -> RunDirectory:
    run_dir = RunDirectory(tmp_path / "run")
    run_dir.open({"limit": None}, _options(*RUN, f"output_dir={tmp_path / 'run'}"), resume=False, recorders=[])
    return run_dir


def test_given_keys_are_the_options_a_command_line_gives():
    assert given_keys(["policy=lerobot", "+a.b=1", "~c", "++d=2", "benchmark.image_size=64", "output_dir=x"]) == {
        "policy.name", "a.b", "c", "d", "benchmark.image_size", "output_dir"}


def test_output_dir_and_resume_alone_resume_with_the_runs_options(run_dir):
    assert _resume(run_dir) == {**_options(*RUN), "output_dir": str(run_dir.path), "resume": True}
    # repeating the run's own options, or choosing its config group again, changes nothing
    assert _resume(run_dir, *RUN, "benchmark=libero_object") == _resume(run_dir)
    # how it runs may change: workers, progress, the limit (a larger one extends the run)
    changed = _resume(run_dir, "workers=2", "progress=false", "limit=4")
    assert (changed["workers"], changed["progress"], changed["limit"], changed["benchmark"]["image_size"]) == (
        2, False, 4, 64)


@pytest.mark.parametrize(("override", "line"), [
    ("benchmark.image_size=128", "benchmark.image_size differs from the run's (64 in run.json, 128 given)"),
    ("benchmark.hard_reset=true", "benchmark.hard_reset differs from the run's (false in run.json, true given)"),
    ("benchmark.episodes_per_task=2", "benchmark.episodes_per_task differs from the run's (1 in run.json, 2 given)"),
    ("horizon=300", "horizon differs from the run's (50 in run.json, 300 given)"),
    ("seed=0", "seed differs from the run's (3 in run.json, 0 given)"),
    ("benchmark=libero_spatial", 'benchmark.name differs from the run\'s ("libero_object" in run.json, '
                                 '"libero_spatial" given)'),
    ("policy=scripted", 'policy.name differs from the run\'s ("random" in run.json, "scripted" given)'),
    ("+policy.chunk=3", "policy.chunk differs from the run's ((unset) in run.json, 3 given)"),
    ("robot.name=franka_droid_fr3", 'robot.name differs from the run\'s (null in run.json, "franka_droid_fr3" given)'),
])
def test_an_option_given_otherwise_is_refused_naming_it_and_both_values(run_dir, override, line):
    with pytest.raises(RunError) as refused:
        _resume(run_dir, *(["benchmark=libero_object"] if override.startswith("benchmark.") else []), override)
    assert str(refused.value) == (f"cannot resume {run_dir.path}: {line}; leave it out to continue the run with its "
                                  "own options, or start a new output_dir")


def test_an_in_process_resume_states_every_option(run_dir):
    """``run_evaluation(config)`` without the command line's keys: the whole config is what was given."""
    given = _options(*RUN, "benchmark.image_size=96", f"output_dir={run_dir.path}", "resume=true")
    with pytest.raises(RunError, match=r": benchmark.image_size differs from the run's \(64 in run.json, 96 given\)"):
        run_dir.resume_options(given, None)
    same = _options(*RUN, "workers=3", f"output_dir={run_dir.path}", "resume=true")
    assert run_dir.resume_options(same, None) == same


def test_a_directory_without_a_run_takes_the_options_as_given(tmp_path):
    given = _options("policy=random", "resume=true")
    assert RunDirectory(tmp_path / "new").resume_options(given, {"policy.name", "resume"}) is given


def test_a_bare_resume_command_composes_in_the_runs_groups(tmp_path, monkeypatch):
    """``output_dir=X resume=true`` and ``dataset_id=D resume=true`` get the run's benchmark and policy
    choices where the command line names none (an option of the run's group then reaches the resume's check)."""
    from molmo_lerobot.cli.eval import _resume_in_the_runs_groups
    from molmo_lerobot.namespaces import DatasetStore

    (tmp_path / "run.json").write_text(json.dumps({"options": {
        "benchmark": {"name": "pusht", "path": None, "image_size": 64}, "policy": {"name": "random"}}}))
    argv = ["molmo-eval", f"output_dir={tmp_path}", "resume=true", "benchmark.image_size=128"]
    _resume_in_the_runs_groups(argv)
    assert argv[1:] == ["policy=random", "benchmark=pusht", f"output_dir={tmp_path}", "resume=true",
                        "benchmark.image_size=128"]
    given = ["molmo-eval", f"output_dir={tmp_path}", "resume=true", "policy=scripted"]
    _resume_in_the_runs_groups(given)
    assert given[1:] == ["benchmark=pusht", f"output_dir={tmp_path}", "resume=true", "policy=scripted"]
    monkeypatch.setattr(DatasetStore, "run_dir", lambda self, dataset_id: tmp_path)
    by_id = ["molmo-eval", "dataset_id=me/run", "resume=true"]
    _resume_in_the_runs_groups(by_id)
    assert by_id[1:3] == ["policy=random", "benchmark=pusht"]
    fresh = ["molmo-eval", f"output_dir={tmp_path}", "benchmark.image_size=128"]  # not a resume: untouched
    _resume_in_the_runs_groups(fresh)
    assert fresh == ["molmo-eval", f"output_dir={tmp_path}", "benchmark.image_size=128"]
