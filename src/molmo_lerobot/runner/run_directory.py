"""A run's output directory: the files the runner owns there, and how a resume reads them back.

``run.json`` says what the run is (benchmark, policy, robots, seed, timing, options, recording
options, the code's version and commit) and holds the options it was started with (``options``).
A resume takes its options from there: ``output_dir=X resume=true`` is the whole command; an option
given again that differs from the run's is refused with one line naming it and both values
(:meth:`RunDirectory.resume_options`), and what the options do not say (the code, MuJoCo, the
benchmark's content, the robots' models) must match too, or the resume is refused naming it.

``episodes.jsonl`` gets each finished episode appended durably (flushed and fsynced) as it
completes; a write that fails (full disk) is cut back to the last whole record, so the file always
parses. ``results.json``, the score, is written atomically only once every episode is accounted
for: a directory without it holds a partial run, and a resume removes it before running anything.
``resume=true`` on the same directory runs again the episodes that are not recorded, recorded with
an infrastructure error (worker died, full disk, policy server gone), with an output that was not
written, or absent from a recorder's output (the dataset of a killed run); it never drops a
recorded episode (a larger ``limit`` extends the run, a smaller one is refused, none keeps the
recorded one). A run recorded with ``record=true`` resumes only with the same recording options
(``dataset/`` would mix encodings or lack the new episodes); one run without may resume recorded
(the dataset gets every episode it lacks). A directory whose run finished no episode does not
block a fresh run there: the fresh run replaces it (:meth:`RunDirectory.open`). What the
finalizers write (``dataset/``, ``report.html``) is theirs.
"""

from __future__ import annotations

import contextlib
import copy
import json
import os
import sys
from collections.abc import Collection
from pathlib import Path
from typing import Any

from molmo_lerobot import fileio
from molmo_lerobot.errors import RunError
from molmo_lerobot.export.shards import SHARDS_DIR
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.results import EPISODES_FILE, RESULTS_FILE, EpisodeResult, RunFileError, RunSummary, read_run

RUN_FILE = "run.json"

#: ``run.json`` fields a resume must find unchanged (``recording``: see :func:`_check_recording`); the options
#: that change a benchmark's episodes (seed, horizon, the suite's options) before ``benchmark``, so a refusal
#: names the cause, not the benchmark's sha256
RUN_IDENTITY = ("robots", "policy", "policy_checkpoint", "seed", "horizon", "timing", "mujoco", "eval_options",
                "code", "render_profile",
                "selection",  # selection: episodes=[…] / sample=K (runner/selection.py); null for limit
                "benchmark")
#: options a resume may give anew (how it runs, not what it evaluates); ``limit`` and the recording options
#: have their own rules (a larger limit extends the run: :meth:`RunDirectory._reopen`; :func:`_check_recording`)
RESUME_FREE = frozenset({"workers", "worker_threads", "executor", "output_dir", "resume", "progress",
                         "progress_interval_s", "episode_timeout_s", "episode_retries", "push", "hub", "wandb",
                         "dataset_id", "limit", "record", "record_hold_steps", "record_min_frames",
                         "record_environment_state", "video"})
_UNSET = object()


class RunDirectory:
    """The files of one run under :attr:`path` (see the module docstring)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    @property
    def run_file(self) -> Path:
        return self.path / RUN_FILE

    @property
    def episodes_file(self) -> Path:
        return self.path / EPISODES_FILE

    @property
    def results_file(self) -> Path:
        return self.path / RESULTS_FILE

    def write_error(self, what: str, exc: OSError) -> RunError:
        """The :class:`RunError` for a write of ``what`` that failed."""
        return RunError(f"cannot write {what} in output_dir {self.path}: {exc.strerror or exc}; finished episodes are "
                        f"kept in {EPISODES_FILE} (fix it, then rerun with resume=true)")

    # Starting -------------------------------------------------------------------------------
    def _recorded(self) -> dict[str, Any] | None:
        """``run.json`` of the run in this directory; ``None`` where there is none (nothing to resume)."""
        if not self.run_file.exists():
            return None
        try:
            previous = json.loads(self.run_file.read_text())
        except (OSError, ValueError, RecursionError):
            previous = None
        if not isinstance(previous, dict):
            raise RunError(f"cannot resume: {self.run_file} is not a run description (not a JSON object)")
        return previous

    def recorded_limit(self) -> int | None:
        """The ``limit`` a run already in this directory was started with (``None``: none, or no run)."""
        limit = (self._recorded() or {}).get("limit")
        return limit if isinstance(limit, int) and not isinstance(limit, bool) and limit >= 1 else None

    def resume_options(self, given: dict[str, Any], keys: Collection[str] | None) -> dict[str, Any]:
        """The options a resume of this directory's run runs with: the run's (``run.json``'s ``options``), with
        the options ``keys`` of ``given`` (dotted keys, what the command line gave; ``None``: every option, as
        an in-process caller states the whole run) where they may change (:data:`RESUME_FREE`). Any other
        given option that differs from the run's is refused, one line naming it and both values. ``given``
        as it is where the directory holds no run yet."""
        recorded = self._recorded()
        if recorded is None:
            return given
        options = recorded.get("options")
        if not isinstance(options, dict):
            raise RunError(f"cannot resume {self.path}: {self.run_file} records no options (a run started by an "
                           "older molmo-lerobot); finish it with the code that started it, or start a new output_dir")
        given = json.loads(json.dumps(given))  # compare as stored (JSON turns int keys into strings)
        merged = copy.deepcopy(options)
        for key in sorted(keys if keys is not None else {*given, *options}):
            path = key.split(".")
            new, old = _get(given, path), _get(options, path)
            if new == old:
                continue
            if path[0] not in RESUME_FREE:
                where, was, now = _first_difference(old, new, key)
                raise RunError(f"cannot resume {self.path}: {where} differs from the run's ({_short(was)} in "
                               f"{RUN_FILE}, {_short(now)} given); leave it out to continue the run with its own "
                               "options, or start a new output_dir")
            _put(merged, path, new)
        return merged

    def open(self, run_info: dict[str, Any], options: dict[str, Any], resume: bool,
             recorders: list[Any]) -> list[EpisodeResult]:
        """Create the directory for the run ``run_info`` describes, started with ``options`` (or reopen it on
        ``resume``), and return the episodes already done that stand. A run there that finished no episode
        is replaced by this one (it has nothing to keep)."""
        out = self.path
        if out.exists() and not out.is_dir():
            raise RunError(f"output_dir {out} is a file, not a directory; choose another output_dir")
        try:
            if out.exists() and any(out.iterdir()):
                if resume:
                    return self._reopen(run_info, recorders)
                if not self._finished_nothing():
                    raise RunError(f"output_dir {out} already holds a run; pass resume=true to continue it "
                                   "or choose another output_dir")
                print(f"molmo-eval: output_dir {out} holds a run that finished no episode; this run replaces it",
                      file=sys.stderr)
                fileio.rmtree(out / SHARDS_DIR, root=out, ignore_errors=True)  # what its recorder began
            run_file = {**run_info, "options": options}
            atomic_write(self.run_file, json.dumps(run_file, indent=2) + "\n", root=out)  # makes ``out`` too
            atomic_write(self.episodes_file, "", root=out)
        except OSError as exc:
            raise RunError(f"cannot write output_dir {out}: {exc.strerror or exc}") from None
        return []

    def _finished_nothing(self) -> bool:
        """Whether this directory holds a run (``run.json``) that finished no episode and wrote no score."""
        if not self.run_file.is_file() or self.results_file.exists():
            return False
        try:
            return not read_run(self.path, finished=False).episodes
        except RunFileError:
            return False

    def _reopen(self, run_info: dict[str, Any], recorders: list[Any]) -> list[EpisodeResult]:
        """Check that the directory holds this same run and return its recorded episodes that stand;
        the others (:meth:`_incomplete`) are dropped from ``episodes.jsonl`` and run again."""
        out, run_file = self.path, self.run_file
        previous = self._recorded()
        if previous is None:
            raise RunError(f"cannot resume: {run_file} is missing")
        current = json.loads(json.dumps(run_info))  # compare as stored (JSON turns int keys into strings)
        for key in RUN_IDENTITY:
            if key == "robots" and previous.get(key) != current.get(key):
                raise RunError(f"cannot resume {out}: it ran {robots_named(previous.get(key))}, this run would run "
                               f"{robots_named(current.get(key))}; finish it with its robots, or start a new "
                               "output_dir")
            if previous.get(key) != current.get(key):
                where, was, now = _first_difference(previous.get(key), current.get(key), key)
                hint = ("; finish it with the code that started it, or start a new output_dir" if key == "code"
                        else "")
                raise RunError(f"cannot resume {out}: its {key} differs from this run's ({where}: {_short(was)} vs "
                               f"{_short(now)}){hint}")
        _check_recording(out, previous.get("recording"), current.get("recording"))
        try:
            done = read_run(out, finished=False).episodes
        except RunFileError as exc:
            raise RunError(f"cannot resume: {exc}; delete that line to run its episode again") from None
        old, new = previous.get("limit"), current["limit"]
        if new is not None and (old is None or new < old):
            recorded, shown = len(done), "null" if old is None else old
            raise RunError(f"cannot resume {out} with limit={new}: it was started with limit={shown} "
                           f"({recorded} episode{'s' * (recorded != 1)} recorded) and a resume never drops recorded "
                           + ("episodes; use limit=null" if old is None else
                              f"episodes; use limit={old} or larger (or leave limit out to keep {old})"))
        rerun = self._incomplete(done, recorders)
        if rerun:
            print(f"molmo-eval: resume runs {len(rerun)} recorded episodes again ({sorted(rerun)[:10]}"
                  f"{' …' if len(rerun) > 10 else ''}): infrastructure errors, outputs not written or not in the "
                  "dataset", file=sys.stderr)
            done = [r for r in done if r.episode_index not in rerun]
        total = current["benchmark"]["n_episodes"]
        planned = total if new is None else min(new, total)
        print(f"molmo-eval: resume {out}: {len(done)} of {planned} episodes recorded stand, running the other "
              f"{planned - len(done)} (limit={'null' if new is None else new}"
              f"{' as recorded' if new == old else f', was {old}'}, of {total} in the benchmark)", file=sys.stderr)
        fileio.remove(self.results_file, root=out)  # partial again until every episode is accounted for
        atomic_write(self.episodes_file, "".join(json.dumps(r.to_dict()) + "\n" for r in done), root=out)
        if new != old:  # a larger limit extends the run
            options = {**previous["options"], "limit": new}
            atomic_write(run_file, json.dumps({**previous, "limit": new, "options": options}, indent=2) + "\n",
                         root=out)
        return done

    def _incomplete(self, done: list[EpisodeResult], recorders: list[Any]) -> set[int]:
        """Recorded episodes a resume runs again: infrastructure failures, episodes with an output not
        written, and those a recorder's output lacks (``RecorderFactory.missing``)."""
        rerun = {r.episode_index for r in done if r.rerun_on_resume or r.output_errors}
        standing = [r for r in done if r.episode_index not in rerun]
        for factory in recorders:
            try:
                rerun |= set(factory.missing(self.path, standing))
            except Exception as exc:
                raise RunError(f"cannot resume {self.path}: {type(factory).__name__} cannot tell which episodes its "
                               f"output lacks: {type(exc).__name__}: {exc}".splitlines()[0]) from None
        return rerun

    # Running and scoring --------------------------------------------------------------------
    def episode_log(self) -> EpisodeLog:
        """``episodes.jsonl`` opened for appending (close it when the run ends)."""
        return EpisodeLog(self)

    def write_scored(self, results: list[EpisodeResult], summary: RunSummary) -> str:
        """``episodes.jsonl`` in episode order and then ``results.json`` (the score, before any export);
        returns the ``results.json`` text written."""
        scored = summary.to_json()
        try:
            atomic_write(self.episodes_file, "".join(json.dumps(r.to_dict()) + "\n" for r in results), root=self.path)
            atomic_write(self.results_file, scored, root=self.path)
        except OSError as exc:
            raise self.write_error("the run's outputs", exc) from None
        return scored

    def update_results(self, summary: RunSummary, scored: str) -> None:
        """Rewrite ``results.json`` if ``summary`` changed since ``scored`` (what the export added: push
        status, failures; the score is the same)."""
        text = summary.to_json()
        if text != scored:
            atomic_write(self.results_file, text, root=self.path)


class EpisodeLog:
    """``episodes.jsonl`` opened for appending whole records: a failed write (full disk) is cut
    back to the last whole record, so the file always parses for resume."""

    def __init__(self, run_dir: RunDirectory) -> None:
        self.run_dir = run_dir
        self.fd = fileio.open_fd(run_dir.episodes_file, os.O_WRONLY | os.O_APPEND, root=run_dir.path)

    def append(self, result: EpisodeResult) -> None:
        data = (json.dumps(result.to_dict()) + "\n").encode()
        start = os.fstat(self.fd).st_size
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(self.fd, view):]
            os.fsync(self.fd)
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.ftruncate(self.fd, start)
            raise self.run_dir.write_error(f"episode {result.episode_index}", exc) from None

    def close(self) -> None:
        os.close(self.fd)


def _check_recording(out: Path, previous: Any, current: Any) -> None:
    """A recorded run resumes only with its recording options (``run.json``'s ``recording``);
    a run recorded nothing may start recording (the dataset gets every episode it lacks)."""
    if previous is None or previous == current:
        return
    if current is None:
        raise RunError(f"cannot resume {out} with record=false: it was started with record=true and its dataset/ "
                       "would lack the episodes run now; resume with record=true (and its recording options)")
    where, was, now = _first_difference(previous, current, "")
    raise RunError(f"cannot resume {out}: its recording option {where} differs from this run's ({_short(was)} vs "
                   f"{_short(now)}); one dataset has one set of recording options: resume with "
                   f"{where}={was if isinstance(was, str) else _short(was)}, or start a new output_dir")


def robots_named(robots: Any) -> str:
    """``run.json``'s ``robots`` in words: ``robot franka_droid (sha256 0123456789ab…)``."""
    if not isinstance(robots, list) or not robots:
        return "no robot"
    names = [f"{r.get('name')} (sha256 {str(r.get('sha256'))[:12]}…)" if isinstance(r, dict) and r.get("sha256")
             else str(r.get("name") if isinstance(r, dict) else r) for r in robots]
    return f"robot{'s' * (len(names) != 1)} {', '.join(names)}"


def _get(tree: Any, path: list[str]) -> Any:
    """The value at ``path`` in nested mappings (:data:`_UNSET` where there is none)."""
    for part in path:
        if not isinstance(tree, dict) or part not in tree:
            return _UNSET
        tree = tree[part]
    return tree


def _put(tree: dict[str, Any], path: list[str], value: Any) -> None:
    """Set (or, for :data:`_UNSET`, remove) the value at ``path`` in nested mappings."""
    for part in path[:-1]:
        tree = tree.setdefault(part, {})
    if value is _UNSET:
        tree.pop(path[-1], None)
    else:
        tree[path[-1]] = value


def _first_difference(a: Any, b: Any, where: str) -> tuple[str, Any, Any]:
    """The dotted key of the first leaf where ``a`` and ``b`` differ, and its two values."""
    if isinstance(a, dict) and isinstance(b, dict):
        for key in [*a, *(k for k in b if k not in a)]:
            if a.get(key) != b.get(key):
                return _first_difference(a.get(key), b.get(key), f"{where}.{key}" if where else str(key))
    return where, a, b


def _short(value: Any, limit: int = 80) -> str:
    """``value`` as JSON, cut to ``limit`` characters (a whole policy config is no error message)."""
    text = "(unset)" if value is _UNSET else json.dumps(value, sort_keys=True)
    return text if len(text) <= limit else text[: limit - 1] + "…"
