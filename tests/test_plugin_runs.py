"""Plugins in real ``molmo-eval`` runs: clashes and pins reach the workers, broken run-time
hooks leave runs untouched, and ``molmo-eval`` is a Hydra app (``-m`` sweeps, ``--help``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from eval_runs import evaluate, molmo_eval, refusal
from test_plugins import IMPOSTOR, write_dist

FAST = ["policy=random", "limit=2", "horizon=3", "workers=1", "progress=false"]
BROKEN_RECORDER = """
from molmo_lerobot import hookimpl

@hookimpl
def molmo_recorders(config):
    raise AttributeError("module 'lerobot' has no attribute 'OldRecorderApi'")
"""
BROKEN_OVERRIDE = """
from molmo_lerobot import hookimpl

@hookimpl
def molmo_episode_overrides(episode, config):
    return episode.nonexistent_field
"""


@pytest.fixture
def install(monkeypatch):
    """``install(root, *modules)``: put a plugin distribution on the path of this process and its workers."""
    modules: list[str] = []

    def _install(root: Path, *names: str) -> None:
        monkeypatch.syspath_prepend(str(root))
        monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (str(root), os.environ.get("PYTHONPATH")) if p))
        modules.extend(names)

    yield _install
    for name in modules:
        sys.modules.pop(name, None)


def _episodes(run: Path) -> list[dict]:
    rows = [json.loads(line) for line in (run / "episodes.jsonl").read_text().splitlines()]
    return [{k: r[k] for k in ("episode_index", "success", "steps", "seed", "error")} for r in rows]


def test_a_clash_fails_the_run_naming_both_and_a_pin_runs_on_the_chosen_provider(install, tmp_path, monkeypatch):
    install(write_dist(tmp_path / "site", "impostor-bots", {"impostor_bots": IMPOSTOR},
                       {"impostor_franka": "impostor_bots"}), "impostor_bots")
    marker = tmp_path / "impostor-built"
    monkeypatch.setenv("IMPOSTOR_MARKER", str(marker))

    [err] = refusal(*FAST, f"output_dir={tmp_path / 'clash'}")
    assert err.startswith("robot 'franka' is provided by plugin 'franka' (molmo-lerobot ")
    assert "plugin 'impostor_franka' (impostor-bots 0.1)" in err
    assert not (tmp_path / "clash" / "results.json").exists() and not marker.exists()

    out = tmp_path / "pinned"
    evaluate(*FAST, "plugins.prefer.robot.franka=impostor_franka", f"output_dir={out}")
    summary = json.loads((out / "results.json").read_text())
    assert (summary["n_episodes"], summary["n_errors"]) == (2, 0)
    assert summary["eval_options"]["plugins_prefer"] == {"robot": {"franka": "impostor_franka"}}  # provenance
    assert summary["robots"][0]["name"] == "franka" and summary["robots"][0]["version"] == "impostor-bots 0.1"
    refused = refusal(*FAST, "plugins.prefer.robot.franka=franka", f"output_dir={out}", "resume=true")
    assert ("plugins.prefer.robot.franka differs from the run's (\"impostor_franka\" in run.json, \"franka\" "
            "given)") in "\n".join(refused)  # never mixes providers in one run
    built_in = {int(pid) for pid in marker.read_text().split()}
    assert built_in and os.getpid() not in built_in  # the workers built the pinned impostor

    evaluate(*FAST, "plugins.prefer.robot.franka=franka", f"output_dir={tmp_path / 'builtin'}")
    assert {int(pid) for pid in marker.read_text().split()} == built_in  # the built-in never touches it


def test_broken_recorder_and_override_plugins_leave_other_runs_untouched(install, tmp_path, capsys):
    evaluate(*FAST, f"output_dir={tmp_path / 'clean'}")
    install(write_dist(tmp_path / "site", "broken-hooks",
                       {"broken_recorder": BROKEN_RECORDER, "broken_override": BROKEN_OVERRIDE},
                       {"bad_recorder": "broken_recorder", "bad_override": "broken_override"}),
            "broken_recorder", "broken_override")
    capsys.readouterr()
    evaluate(*FAST, f"output_dir={tmp_path / 'with_broken'}")
    err = capsys.readouterr().err
    assert "plugin 'bad_recorder' (broken-hooks 0.1) is broken and was skipped: molmo_recorders() failed: " \
           "AttributeError: module 'lerobot' has no attribute 'OldRecorderApi'" in err
    assert "plugin 'bad_override' (broken-hooks 0.1) is broken and was skipped: molmo_episode_overrides() " \
           "failed: AttributeError:" in err
    assert _episodes(tmp_path / "with_broken") == _episodes(tmp_path / "clean")
    assert all(e["error"] is None for e in _episodes(tmp_path / "with_broken"))


def test_a_sweep_writes_one_complete_run_per_job_and_a_failing_job_does_not_stop_the_others(tmp_path):
    sweep = tmp_path / "sweep"
    proc = molmo_eval("-m", "workers=0,1", "policy=random,scripted", "limit=2", "horizon=3", "progress=false",
                      f"hydra.sweep.dir={sweep}")
    assert proc.returncode == 2 and "Launching 4 jobs locally" in proc.stderr
    assert proc.stderr.count("molmo-eval: error: workers must be at least 1, got 0") == 2
    jobs = sorted(p.parent.name for p in sweep.glob("*/results.json"))
    assert jobs == ["2-random-pick_v1", "3-scripted-pick_v1"]  # the refused jobs have no run
    for job, policy in zip(jobs, ("random", "scripted"), strict=True):
        summary = json.loads((sweep / job / "results.json").read_text())
        assert (summary["policy"]["name"], summary["n_episodes"]) == (policy, 2)
        assert len(_episodes(sweep / job)) == 2 and f"outputs: {sweep / job}" in proc.stdout
    assert (sweep / "multirun.yaml").is_file()
    # the sweep ends with one table of its jobs (each job's own summary scrolled by above it)
    table = proc.stdout.strip().splitlines()[-6:]
    assert table[0] == "sweep: 4 jobs"
    assert table[1].split() == ["job", "policy", "benchmark", "success", "exit", "outputs"]
    assert table[2].split()[:4] == ["0", "random", "pick_v1", "error:"] and table[2].split()[-2:] == ["2", "-"]
    assert table[4].split()[:3] == ["2", "random", "pick_v1"] and table[4].split()[-2:] == [
        "0", str(sweep / "2-random-pick_v1")]


def test_a_single_run_writes_nothing_but_its_output_dir(tmp_path):
    proc = molmo_eval(*FAST, "output_dir=out", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stdout.endswith("outputs: out\n"), proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_help_is_hydras_app_help_with_every_config_group():
    proc = molmo_eval("--help")
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert out.startswith("usage: molmo-eval [-m]")
    listing = out.split("== Config groups ==")[1].split("==")[0].strip()
    groups = dict(line.split(": ", 1) for line in listing.splitlines())
    assert {"random", "scripted", "lerobot"} <= set(groups["policy"].split(", "))
    assert "--multirun" in out and "--cfg" in out


CONFIG_PLUGIN = """
from pathlib import Path
from molmo_lerobot import hookimpl

@hookimpl
def molmo_config_dirs():
    return [str(Path(__file__).parent / "sine_conf")]
"""


def test_plugin_config_dirs_join_the_search_path_of_compose_and_the_app(install, tmp_path):
    from molmo_lerobot.config import compose

    root = write_dist(tmp_path / "site", "sine-configs", {"sine_configs": CONFIG_PLUGIN}, {"sine_cfg": "sine_configs"})
    (root / "sine_conf" / "policy").mkdir(parents=True)
    (root / "sine_conf" / "policy" / "sine.yaml").write_text("name: sine\namplitude: 0.1\n")
    install(root, "sine_configs")
    assert compose(["policy=sine", "policy.amplitude=0.3"]).policy == {"name": "sine", "amplitude": 0.3}
    res = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.eval", "--info", "searchpath"],
                         capture_output=True, text=True, timeout=300)  # PYTHONPATH from install()
    assert res.returncode == 0 and f"| molmo-plugin | file://{root / 'sine_conf'}" in res.stdout
