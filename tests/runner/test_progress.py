"""Readable progress: steps inside running episodes, plain lines off a terminal, worker prints kept apart."""

from __future__ import annotations

import io
import subprocess
import sys
import time

from molmo_lerobot.runner.progress import Progress, StepProgressFactory, running_episodes


class _Info:
    episode_index, horizon = 3, 303


def test_off_a_terminal_one_line_per_update_and_a_heartbeat_with_steps(tmp_path):
    stream = io.StringIO()  # not a terminal
    with Progress(4, 0, "pick_v1 · p", tmp_path, stream=stream, heartbeat_s=0.2, refresh_s=0.05) as progress:
        rec = StepProgressFactory(interval_s=0.0).make("w0g0", tmp_path)
        rec.start_episode(_Info())
        for _ in range(120):
            rec.record_step(None, None, None, False, False)
        assert running_episodes(tmp_path) == [{"episode": 3, "step": 120, "horizon": 303}]
        progress.episode_done(True, False)
        time.sleep(0.5)  # heartbeats while episode 3 runs
        rec.end_episode(None)
        progress.episode_done(False, True)
    text = stream.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    done_line = lines.index(next(ln for ln in lines if "1/4" in ln))
    assert lines[done_line].startswith("pick_v1 · p: 1/4 episodes (25%) success=1.00 errors=0 | running: ep 3 120/303")
    assert any("1/4 episodes" in ln and "running: ep 3 120/303" in ln for ln in lines[done_line + 1:-1]), lines
    assert lines[-1].startswith("pick_v1 · p: 2/4 episodes (50%) success=0.50 errors=1 [")
    assert not (tmp_path / ".progress").exists()


def test_disabled_progress_prints_nothing_and_adds_no_recorder(tmp_path):
    stream = io.StringIO()
    with Progress(2, 0, "x", tmp_path, enabled=False, stream=stream) as progress:
        progress.episode_done(True, False)
        assert progress.factories() == []
    assert stream.getvalue() == ""


def test_worker_output_goes_to_its_log_file(tmp_path):
    code = ("import os, sys; from molmo_lerobot.runner.progress import redirect_worker_output; "
            f"redirect_worker_output({str(tmp_path)!r}, 'w0g0'); print('Loading weights from checkpoint'); "
            "sys.stderr.write('UserWarning: something\\n'); os.write(2, b'C-level warning\\n')")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout == "" and proc.stderr == ""
    log = (tmp_path / "logs" / "w0g0.log").read_text()
    assert "Loading weights" in log and "UserWarning" in log and "C-level warning" in log


def test_molmo_eval_off_a_terminal_prints_plain_lines_with_steps(faulty_policy, small_bench, tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "molmo_lerobot.cli.eval", f"benchmark.path={small_bench}", "policy=faulty",
         "workers=1", "limit=2", "horizon=40", "policy.act_sleep_s=0.05",
         f"policy.marker_dir={faulty_policy.marker_dir}",
         f"output_dir={out}", "progress_interval_s=0.5"],
        capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "\r" not in proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("pick_small · faulty:")]
    assert any("0/2 episodes" in ln and "running: ep 0 " in ln for ln in lines), proc.stderr
    assert lines[-1].startswith("pick_small · faulty: 2/2 episodes (100%)")
    assert (out / "logs" / "w0g0.log").exists()


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_on_a_terminal_library_warnings_print_above_the_bar(tmp_path, monkeypatch):
    """Ray's token warning (a ``ray`` logger record) goes through tqdm.write, never into the bar line."""
    import logging

    term = _Terminal()
    ray_logger = logging.getLogger("ray")
    handler = logging.StreamHandler(term)
    monkeypatch.setattr(ray_logger, "handlers", [handler])
    monkeypatch.setattr(ray_logger, "propagate", False)
    monkeypatch.setattr(sys, "stderr", term)  # tqdm's logging redirect replaces handlers writing to stderr
    handler.stream = sys.stderr
    with Progress(2, 0, "bench · p", tmp_path, stream=term) as progress:
        progress.episode_done(True, False)
        ray_logger.warning("Token authentication is disabled for this Ray cluster.")
        progress.episode_done(True, False)
    screen = [seg for line in term.getvalue().split("\n") for seg in line.split("\r")]
    assert "Token authentication is disabled for this Ray cluster." in screen  # a line of its own
    assert any(seg.startswith("bench · p: 100%") for seg in screen)
    assert ray_logger.handlers == [handler]  # restored after the run


LIBRARY_BARS = """
import sys
from molmo_lerobot.runner.progress import quiet_library_bars
quiet_library_bars()  # what molmo-eval does before anything imports tqdm
import tqdm  # LeRobot's dataset merge draws tqdm.tqdm bars (lerobot/datasets/aggregate.py)
for _ in tqdm.tqdm(range(3), desc="Copy data and videos"):
    pass
"""


def test_off_a_terminal_the_libraries_draw_no_progress_bars():
    """LeRobot's merge bars (tqdm) would put every redraw in a log; on a terminal they stay."""
    import os

    env = {k: v for k, v in os.environ.items() if not k.startswith("TQDM_")}
    proc = subprocess.run([sys.executable, "-c", LIBRARY_BARS], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Copy data and videos" not in proc.stderr and "\r" not in proc.stderr, proc.stderr
