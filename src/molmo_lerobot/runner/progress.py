"""Run progress a person can read: episodes done, steps inside the running episodes, nothing else in the way.

* Workers report their step inside the current episode through a tiny file per worker
  (``output_dir/.progress/<worker_id>.json``, rewritten at most every ``interval_s``) written by
  :class:`StepProgressRecorder`; the main process reads them, so no executor protocol changes
  (workers of a remote Ray cluster write on their own machines: there it shows elapsed time only).
* On a terminal: one tqdm bar, its postfix naming the running episodes and their steps,
  refreshed every second. Log records (Ray's, ours) print above the bar, never through it.
* Not a terminal (CI logs, ``| tee``): one plain line per finished episode, plus a heartbeat
  line every ``heartbeat_s`` while episodes run; never carriage returns.
* Workers write their own stdout/stderr (weight-loading prints, library warnings) to
  ``output_dir/logs/<worker_id>.log`` (:func:`redirect_worker_output`), so they cannot break the bar.
* Not a terminal: the libraries' own tqdm progress bars (LeRobot's dataset merge, ``datasets``) are
  off (:func:`quiet_library_bars`); a log would hold every redraw.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.recording import EpisodeInfo, Recorder, RecorderFactory

PROGRESS_DIR = ".progress"
LOGS_DIR = "logs"


def quiet_library_bars(stream: IO[str] | None = None) -> None:
    """Turn the libraries' tqdm bars off unless ``stream`` (default stderr) is a terminal. Call it before
    tqdm is imported (it reads ``TQDM_*`` then); processes started later inherit it. A variable the
    user set wins."""
    stream = sys.stderr if stream is None else stream
    if not getattr(stream, "isatty", lambda: False)():
        # TQDM_DISABLE alone: datasets' and the Hub's own switches warn when a library turns bars back on
        os.environ.setdefault("TQDM_DISABLE", "1")


def redirect_worker_output(output_dir: str | Path, worker_id: str) -> Path | None:
    """Point this worker process's stdout and stderr (file descriptors 1 and 2) at its log file.

    Kept on the console when ``MOLMO_DEBUG`` is set (tracebacks are wanted there), or when the log
    would be written through a link inside the run directory (refused, with a warning).
    """
    if os.environ.get("MOLMO_DEBUG"):
        return None
    path = Path(output_dir) / LOGS_DIR / f"{worker_id}.log"
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    try:
        fd = fileio.open_fd(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644, root=output_dir)
    except fileio.UnsafePathError as exc:
        print(f"molmo-eval: warning: worker output stays on the console: {exc}", file=sys.stderr, flush=True)
        return None
    except OSError:  # e.g. a remote Ray node without the output directory: keep Ray's own log capture
        return None
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    return path


@dataclass
class StepProgressFactory(RecorderFactory):
    """Picklable recipe for :class:`StepProgressRecorder`."""

    interval_s: float = 0.5

    def make(self, worker_id: str, output_dir: Path) -> StepProgressRecorder:
        return StepProgressRecorder(Path(output_dir), worker_id, self.interval_s)


class StepProgressRecorder(Recorder):
    """Writes ``{"episode", "step", "horizon"}`` of the running episode, at most every ``interval_s``."""

    wants_images = False

    def __init__(self, output_dir: Path, worker_id: str, interval_s: float) -> None:
        self.root, self.interval_s = output_dir, interval_s
        self.path = output_dir / PROGRESS_DIR / f"{worker_id}.json"
        self._episode = self._horizon = self._step = 0
        self._last = 0.0

    def start_episode(self, info: EpisodeInfo) -> None:
        self._episode, self._horizon, self._step = info.episode_index, info.horizon, 0
        self._write()

    def record_step(self, obs: Any, action: Any, reward: float | None, success: bool, done: bool) -> None:
        self._step += 1
        if time.monotonic() - self._last >= self.interval_s:
            self._write()

    def end_episode(self, result: Any) -> None:
        fileio.remove(self.path, root=self.root)

    def close(self) -> None:
        fileio.remove(self.path, root=self.root)

    def _write(self) -> None:
        self._last = time.monotonic()
        atomic_write(self.path, json.dumps({"episode": self._episode, "step": self._step, "horizon": self._horizon}),
                     root=self.root, durable=False)


def running_episodes(output_dir: Path) -> list[dict[str, int]]:
    """What the workers are doing now, from their progress files (episode order)."""
    out = []
    for f in sorted((Path(output_dir) / PROGRESS_DIR).glob("*.json")):
        try:
            out.append(json.loads(f.read_text()))
        except (OSError, ValueError):
            continue  # replaced or removed while reading
    return sorted(out, key=lambda r: r.get("episode", 0))


def _fmt_time(s: float) -> str:
    s = int(s)
    return f"{s // 3600}h{s % 3600 // 60:02d}m{s % 60:02d}s" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


class Progress:
    """The run's progress display (a context manager); see the module docstring."""

    def __init__(self, total: int, initial: int, desc: str, output_dir: Path, *, enabled: bool = True,
                 stream: IO[str] | None = None, heartbeat_s: float = 30.0, refresh_s: float = 1.0) -> None:
        self.total, self.done, self.desc = total, initial, desc
        self.output_dir = Path(output_dir)
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.heartbeat_s, self.refresh_s = heartbeat_s, refresh_s
        self.success = self.errors = 0
        self._bar: Any = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._t0 = time.monotonic()
        self._last_line = self._t0
        self._redirect: Any = None

    def factories(self) -> list[RecorderFactory]:
        """The worker-side recorder that reports steps (none when progress is off)."""
        return [StepProgressFactory()] if self.enabled else []

    def __enter__(self) -> Progress:
        fileio.rmtree(self.output_dir / PROGRESS_DIR, root=self.output_dir, ignore_errors=True)
        if not self.enabled:
            return self
        if self.tty:
            from tqdm import tqdm
            from tqdm.contrib.logging import logging_redirect_tqdm

            self._bar = tqdm(total=self.total, initial=self.done, desc=self.desc, unit="ep", file=self.stream)
            self._redirect = logging_redirect_tqdm(loggers=[logging.root, logging.getLogger("ray")])
            self._redirect.__enter__()
        self._thread = threading.Thread(target=self._tick, name="molmo-progress", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
        if self._redirect is not None:
            self._redirect.__exit__(None, None, None)
        if self._bar is not None:
            self._bar.close()
        fileio.rmtree(self.output_dir / PROGRESS_DIR, root=self.output_dir, ignore_errors=True)

    def episode_done(self, success: bool, error: bool) -> None:
        """One more episode is accounted for."""
        with self._lock:
            self.done += 1
            self.success += bool(success)
            self.errors += bool(error)
            if not self.enabled:
                return
            if self._bar is not None:
                self._bar.update(1)
                self._bar.set_postfix_str(self._postfix(), refresh=True)
            else:
                self._line()

    def _postfix(self) -> str:
        rate = f"success={self.success / self.done:.2f} " if self.done else ""
        running = running_episodes(self.output_dir)
        steps = ", ".join(f"ep {r['episode']} {r['step']}/{r['horizon']}" for r in running[:4])
        more = f" +{len(running) - 4}" if len(running) > 4 else ""
        return f"{rate}errors={self.errors}" + (f" | running: {steps}{more}" if steps else "")

    def _line(self) -> None:
        elapsed = time.monotonic() - self._t0
        pct = 100.0 * self.done / self.total if self.total else 100.0
        print(f"{self.desc}: {self.done}/{self.total} episodes ({pct:.0f}%) {self._postfix()} "
              f"[{_fmt_time(elapsed)} elapsed]", file=self.stream, flush=True)
        self._last_line = time.monotonic()

    def _tick(self) -> None:
        while not self._stop.wait(self.refresh_s):
            with self._lock:
                if self._bar is not None:
                    self._bar.set_postfix_str(self._postfix(), refresh=True)
                elif time.monotonic() - self._last_line >= self.heartbeat_s and self.done < self.total:
                    self._line()
