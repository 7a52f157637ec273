"""A suite's env process is the machinery, not the policy: one that dies, hangs or cannot start is an
infrastructure failure, killed, restarted and its episode retried, and it never outlives its worker.

The runs play LIBERO benchmarks over a stand-in LIBERO process (``libero_standin_server.py``) in a fake LIBERO
venv, through the real worker, supervisor and suite pipe; its outcome rule (odd seeds succeed at step 3, even
ones run to the horizon) is the undisturbed run's.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from molmo_lerobot.config import compose
from molmo_lerobot.errors import INFRASTRUCTURE, error_kind
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.suites.libero import LiberoSuite, libero_venv
from molmo_lerobot.suites.pipe import SuiteProcess, SuiteProcessError

STANDIN = Path(__file__).with_name("libero_standin_server.py")
ARGS = ["policy=random", "benchmark=libero_object", "workers=1", "horizon=5", "benchmark.image_size=8",
        "benchmark.episodes_per_task=2", "limit=4", "progress=false"]


def fake_venv(root: Path, server: Path = STANDIN, config: bool = True) -> Path:
    """A LIBERO venv whose ``bin/python`` runs ``server`` with this interpreter, whatever it is asked to run."""
    (root / "bin").mkdir(parents=True)
    python = root / "bin" / "python"
    python.write_text(f'#!/bin/sh\nexec {sys.executable} {server} "$@"\n')
    python.chmod(0o755)
    if config:
        (root / "libero-config").mkdir()
        (root / "libero-config" / "config.yaml").write_text("{}\n")
    return root


@pytest.fixture
def standin(tmp_path, monkeypatch) -> Path:
    """The stand-in's directory (``pids``, ``fault``), its fake venv named by ``MOLMO_LIBERO_VENV``."""
    monkeypatch.setenv("MOLMO_LIBERO_VENV", str(fake_venv(tmp_path / "venv")))
    monkeypatch.setenv("STANDIN_DIR", str(tmp_path))
    return tmp_path


def alive(pid: int) -> bool:
    """Whether ``pid`` is a process that has not ended (a zombie has)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in "ZX"
    except OSError:
        return False


def undisturbed(res) -> None:
    """Every episode as the stand-in plays it undisturbed: odd seeds succeed at step 3, even ones at the horizon."""
    got = [(r.episode_index, r.seed, r.success, r.steps, r.error) for r in res.episodes]
    assert got == [(i, i % 2, i % 2 == 1, 3 if i % 2 else 5, None) for i in range(4)], got


@pytest.mark.parametrize("fault", ["kill", "stop"])
def test_a_suite_process_killed_or_stopped_mid_episode_is_replaced_and_the_episode_retried(standin, tmp_path,
                                                                                           monkeypatch, fault):
    """``kill -9`` (or SIGSTOP: no answer within ``MOLMO_SUITE_TIMEOUT_S``) of the worker's LIBERO process at step
    2 of episode 1: that attempt is an infrastructure failure, a new process plays the retry and every later
    episode, and the run ends as the undisturbed one; no process is left behind."""
    monkeypatch.setenv("MOLMO_SUITE_TIMEOUT_S", "4")
    (standin / "fault").write_text(f"{fault} 1 2\n")
    res = run_evaluation(compose([*ARGS, f"output_dir={tmp_path / 'run'}"]))
    undisturbed(res)
    assert (standin / "fault.done").exists(), "the fault never fired"
    assert [r.attempts for r in res.episodes] == [1, 2, 1, 1]
    pids = [int(p) for p in (standin / "pids").read_text().split()]
    assert len(pids) == 3, "the catalogue's process, the worker's first, its replacement"
    assert not any(alive(p) for p in pids)
    rows = [json.loads(line) for line in (tmp_path / "run" / "episodes.jsonl").read_text().splitlines()]
    assert [r["error"] for r in rows] == [None] * 4


def test_the_suite_process_of_a_killed_worker_dies_with_it_even_when_stopped(standin, tmp_path):
    """A process holding a suite process is SIGKILLed while that suite process is stopped (SIGSTOP): the suite
    process goes too (parent-death signal), not left under init; and a Ctrl-C at the terminal, which reaches the
    holder's process group, does not reach it (a group of its own)."""
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent("""
        import sys, time
        from molmo_lerobot.suites.libero import LiberoSuite, libero_venv
        suite = LiberoSuite()
        print(suite.pid, flush=True)
        time.sleep(600)
    """)], stdout=subprocess.PIPE, text=True, start_new_session=True, env=os.environ)
    try:
        child = int(holder.stdout.readline())
        assert os.getpgid(child) == child != os.getpgid(holder.pid)
        os.kill(child, signal.SIGSTOP)
    finally:
        holder.kill()
        holder.wait()
    deadline = time.monotonic() + 10
    while alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(child)


def test_ctrl_c_while_the_suite_lists_its_tasks_is_one_true_line(standin, tmp_path):
    """Ctrl-C at the terminal (SIGINT to molmo-eval's process group) while the main process waits for LIBERO's task
    catalogue: exit 130 with one line that promises no run directory, no traceback from the LIBERO process (it is
    not in that group), and the LIBERO process is gone."""
    (standin / "slow_tasks").touch()
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "molmo_lerobot.cli.eval", *ARGS, f"output_dir={out}"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while not (standin / "in_tasks").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.splitlines() == [
        "molmo-eval: interrupted while no episode was running (setting the run up or finishing it); where it had "
        "written a run directory, output_dir=<it> resume=true continues the run"], err
    [pid] = [int(p) for p in (standin / "pids").read_text().split()]
    assert not alive(pid) and not out.exists()


def test_a_suite_process_that_never_answers_or_prompts_is_a_bounded_one_line_start_failure(tmp_path, monkeypatch):
    """An interpreter that never says hello: refused after ``MOLMO_SUITE_TIMEOUT_S`` and killed; a server whose
    start asks on stdin (LIBERO's import without its config): refused at once, its stdin being no terminal or pipe
    to wait on. Both one line saying what to do."""
    monkeypatch.setenv("MOLMO_SUITE_TIMEOUT_S", "2")
    (tmp_path / "silent.py").write_text("import time\ntime.sleep(600)\n")
    (tmp_path / "prompting.py").write_text(textwrap.dedent("""
        from molmo_lerobot.suites.pipe import serve
        serve(lambda: {"answer": input("Do you want to specify a custom path for the dataset folder? (Y/N): ")})
    """))
    t0 = time.monotonic()
    with pytest.raises(SuiteProcessError) as silent:
        LiberoSuite(fake_venv(tmp_path / "silent", tmp_path / "silent.py"))
    assert 2 <= time.monotonic() - t0 < 30
    message = str(silent.value)
    assert "took more than 2 s to start (MOLMO_SUITE_TIMEOUT_S sets the limit)" in message
    assert "run `make .libero-venv`" in message and "MOLMO_LIBERO_VENV" in message and "\n" not in message
    assert error_kind(silent.value) == INFRASTRUCTURE
    assert not alive(int(message.split("(process ")[1].split(")")[0]))

    with pytest.raises(SuiteProcessError, match=r"could not start: EOFError: EOF when reading a line; the LIBERO "
                                                r"venv is .*prompting.*`make \.libero-venv`"):
        LiberoSuite(fake_venv(tmp_path / "prompting", tmp_path / "prompting.py"))


def test_a_libero_venv_without_its_config_is_refused_before_any_run_directory(tmp_path, monkeypatch):
    from eval_runs import refusal

    venv = fake_venv(tmp_path / "venv", config=False)
    monkeypatch.setenv("MOLMO_LIBERO_VENV", str(venv))
    out = tmp_path / "out"
    [line] = refusal(*ARGS, f"output_dir={out}")
    assert line.startswith(f"no LIBERO config at {venv}/libero-config/config.yaml (LIBERO would ask for one on "
                           f"stdin); the LIBERO venv is {venv}: run `make .libero-venv` (it builds ")
    assert line.endswith("/.libero-venv and its config) or set MOLMO_LIBERO_VENV to a venv it built")
    assert not out.exists()


@pytest.mark.skipif(not (libero_venv() / "bin" / "python").exists(), reason="no LIBERO venv (make .libero-venv)")
def test_libero_prints_nothing_of_its_own(capfd):
    """LIBERO's ``[info] using task orders …`` (its stdout) is not on every run's terminal."""
    with LiberoSuite(image_size=8) as suite:
        assert len(suite.tasks("libero_object")) == 10
    out, err = capfd.readouterr()
    assert "using task orders" not in out + err


def test_a_bad_suite_timeout_is_refused_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("MOLMO_SUITE_TIMEOUT_S", "soon")
    with pytest.raises(Exception, match=r"^MOLMO_SUITE_TIMEOUT_S: expected a number of seconds > 0, got 'soon'$"):
        SuiteProcess(Path(sys.executable), "molmo_lerobot.suites.libero_server")
