"""``molmo-eval`` in tests: in this process as every in-process caller runs it (compose the overrides,
validate, evaluate), and the console script itself, a Hydra app that reads ``sys.argv``, as a subprocess
(for what is about its command line: ``-m``, ``--help``, ``--cfg``, printed errors, exit statuses)."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from molmo_lerobot.cli.eval import refused_errors
from molmo_lerobot.config import compose
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.evaluate import EvalResults, run_evaluation
from molmo_lerobot.runner.forkserver import ForkServerPool


def evaluate(*overrides: str, fork_servers: ForkServerPool | None = None) -> EvalResults:
    """``molmo-eval *overrides``'s run (its workers' fork server from ``fork_servers``, if given)."""
    return run_evaluation(RunConfig.of(compose(list(overrides))), fork_servers)


def refusal(*overrides: str) -> list[str]:
    """The problems ``molmo-eval *overrides`` refuses with (exit 2), one ``molmo-eval: error:`` line
    each; fails the test where it runs instead."""
    with pytest.raises(refused_errors()) as refused:
        evaluate(*overrides)
    return str(refused.value).splitlines()


def molmo_eval(*args: str, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """``molmo-eval *args`` in a subprocess (this process's environment; text output captured)."""
    return subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.eval", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=timeout)


def interrupted(*args: str, out: Path, after: int, timeout: float = 240) -> str:
    """Ctrl-C ``molmo-eval *args output_dir=out`` once ``after`` episodes are recorded; the command it
    printed to continue the run (the run must stop with 130 and no ``results.json``)."""
    proc = subprocess.Popen([sys.executable, "-m", "molmo_lerobot.cli.eval", *args, f"output_dir={out}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    episodes = out / "episodes.jsonl"
    try:
        deadline = time.monotonic() + timeout
        while not (episodes.exists() and len(episodes.read_text().splitlines()) >= after):
            assert proc.poll() is None and time.monotonic() < deadline, "the run ended or stalled before Ctrl-C"
            time.sleep(0.02)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 128 + signal.SIGINT and not (out / "results.json").exists(), err[-2000:]
    printed = re.search(r"to continue, rerun with (output_dir=\S+ resume=true)$", err.strip())
    assert printed, err[-2000:]
    return printed.group(1)
