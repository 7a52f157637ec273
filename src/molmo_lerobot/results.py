"""Episode results, the run summary (``results.json``) and :func:`read_run`, the one reader of a run.

Every attempted episode counts. An episode that raised, timed out, diverged or whose worker
died is a failure with its ``error`` recorded; it is never dropped from the denominator.
``n_valid`` counts the episodes that simulated (no error). A block in which no episode
simulated measured nothing about the policy: its rates and intervals are ``null`` (not a
0 % score) while every count stays recorded.

An error's ``error_kind`` says whose it is (:mod:`molmo_lerobot.errors`): ``"episode"`` stays
when the run is resumed, ``"infrastructure"`` (worker died, full disk, policy server gone) is
run again. An output that could not be written (a thumbnail, the dataset episode) never
changes the outcome: it is listed in the episode's ``output_errors``.

Two success flags per episode, each with one name wherever it is printed:

* ``success``: the task's success at the final step (the primary metric, ``success_rate``);
* ``success_once``: success at any chunk end: sampled where MolmoSpaces samples it, after each
  action chunk and at the episode's end (``success_once_rate``);
* ``extra.success_any_step`` (``episodes.jsonl`` only): success at any policy step, finer than
  ``success_once`` when a policy plays chunks longer than one step.

Rewards, ``lerobot-eval``'s figures: an episode's ``extra.sum_reward`` and ``extra.max_reward`` over its
steps (the env's reward; ours: the task's own, else 1.0 on success), averaged per block over the
episodes that simulated (``avg_sum_reward``, ``avg_max_reward``).

:class:`RunSummary` is ``results.json``'s schema. ``summarize`` scores the episodes; what runs
after the score (the dataset's Hub push) returns a :data:`SummaryPiece` that the summary takes
in (:meth:`RunSummary.with_piece`), never edits it. A file without ``schema_version`` is
version 1 (runs written before the field existed); version 2 added ``robots`` (the run's and each
task's), which version 1's readers refuse as an unknown field.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, ValidationError

from molmo_lerobot.errors import EPISODE, INFRASTRUCTURE, MolmoError

#: ``results.json``'s ``schema_version`` this code writes and the newest it reads
SCHEMA_VERSION = 2
PRIMARY_METRIC = "success_rate (success at the final step)"
EPISODES_FILE = "episodes.jsonl"
RESULTS_FILE = "results.json"
#: the printed name of each scored success flag (one name, one field; see the module docstring)
SUCCESS_LABELS = {"success": "success at the final step", "success_once": "success at any chunk end"}


class RunFileError(MolmoError, ValueError):
    """A run's ``results.json`` or ``episodes.jsonl`` is missing or malformed: ``<file>[:<line>]: <what>``."""


@dataclass(frozen=True)
class EpisodeIdentity:
    """Which trial an episode is, fixed when it is planned: the
    :class:`~molmo_lerobot.runner.plan.EpisodePlan` owns it and the recorders'
    :class:`~molmo_lerobot.recording.EpisodeInfo` embeds it, so every part of a run sees one value."""

    episode_index: int
    seed: int
    #: the task type's name (the known name when no installed plugin provides it)
    task_type: str
    prompt: str
    #: policy steps and where they came from (``cli``, ``task_horizons``, ``task_horizon_sec``,
    #: ``default``); ``None`` only for an episode whose task type no plugin provides
    horizon: int | None
    horizon_source: str | None
    #: SHA-256 of the episode's canonical JSON as it runs (overrides applied)
    digest: str
    #: where the benchmark's episode says it plays (``None`` for an env suite's episode)
    house_index: int | None = None
    task_cls: str | None = None


class EpisodeOutcome:
    """A live episode's outcome, kept the same way by every episode session (ours and an env suite's):
    ``success`` (the last state), ``success_once`` (at the instants the agent observes, and at the end),
    ``success_any_step`` and what ended it (``ended_by``). A session sets ``end_on_success`` and gives its
    ``horizon``."""

    end_on_success: bool

    @property
    def horizon(self) -> int:
        raise NotImplementedError

    def __init__(self) -> None:
        self.steps = 0
        self.success = self.success_once = self.success_any_step = False
        #: why the episode ended (``horizon``, ``success``, ``terminated`` by the env, ``done``); ``None`` while it runs
        self.ended_by: str | None = None
        #: the last step's reward as the task defines it (``None``: it defines none; what recorders get),
        #: as scored (the task's, else 1.0 on success), and the sum and maximum of the scored one over the
        #: episode's steps (``lerobot-eval``'s ``sum_reward`` and ``max_reward``; ``None`` before the first step)
        self.task_reward: float | None = None
        self.reward = 0.0
        self.sum_reward = 0.0
        self.max_reward: float | None = None

    def count_step(self, success: bool, observed: bool, reward: float | None) -> bool:
        """One more step ending in ``success`` with the task's ``reward`` (``None``: it defines none, and the
        step scores 1.0 on success); ``observed``: the agent sees that state."""
        self.success = success
        self.steps += 1
        self.success_any_step |= success
        if observed:
            self.success_once |= success
        self.task_reward = reward
        reward = float(success) if reward is None else reward
        self.reward = reward
        self.sum_reward += reward
        self.max_reward = reward if self.max_reward is None else max(self.max_reward, reward)
        return success

    def rewards(self) -> dict[str, float]:
        """``sum_reward`` and ``max_reward`` of the steps so far, for the result's ``extra`` (none: no step)."""
        return {} if self.max_reward is None else {"sum_reward": self.sum_reward, "max_reward": self.max_reward}

    def end(self, said_done: bool = False, terminated: bool = False) -> str | None:
        """Whether the episode ends after this step, and why: the action said ``done``, ``success`` (with
        ``end_on_success``, or the env ``terminated`` it), ``terminated`` without success, or the ``horizon``;
        ``None`` while it goes on. Its end is an observation instant (``success_once``)."""
        if said_done:
            self.ended_by = "done"
        elif terminated or (self.end_on_success and self.success):
            self.ended_by = "success" if self.success else "terminated"
        elif self.steps >= self.horizon:
            self.ended_by = "horizon"
        else:
            return None
        self.success_once |= self.success
        return self.ended_by


@dataclass
class EpisodeResult:
    """One attempted episode. The first seven fields are the ``episodes.jsonl`` contract."""

    episode_index: int
    house_index: int | None
    task_cls: str | None
    success: bool
    success_once: bool
    steps: int
    seed: int
    error: str | None = None
    task_type: str | None = None
    prompt: str | None = None
    horizon: int | None = None
    horizon_source: str | None = None  # cli | task_horizons | task_horizon_sec | default
    duration_s: float = 0.0
    attempts: int = 1
    error_kind: str | None = None  # with an error: "episode" | "infrastructure" (resume reruns it)
    output_errors: list[str] = field(default_factory=list)  # outputs not written; the outcome stands
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EpisodeResult:
        known = {k: d[k] for k in cls.__dataclass_fields__ if k in d}
        return cls(**known)

    @classmethod
    def failed(cls, episode_index: int, house_index: int | None, task_cls: str | None, seed: int,
               error: str, error_kind: str = EPISODE, **kw: Any) -> EpisodeResult:
        return cls(episode_index, house_index, task_cls, False, False, 0, seed, error, error_kind=error_kind, **kw)

    @property
    def rerun_on_resume(self) -> bool:
        """An infrastructure failure: it says nothing about the policy, so ``resume=true`` reruns it."""
        return self.error is not None and self.error_kind == INFRASTRUCTURE


_NONE = type(None)
#: ``episodes.jsonl`` fields with their JSON types: the seven every record has, then those it may have
_RECORD_TYPES: dict[str, tuple[type, ...]] = {
    "episode_index": (int,), "house_index": (int, _NONE), "task_cls": (str, _NONE), "success": (bool,),
    "success_once": (bool,), "steps": (int,), "seed": (int,), "error": (str, _NONE),
}
_OPTIONAL_TYPES: dict[str, tuple[type, ...]] = {
    "task_type": (str, _NONE), "prompt": (str, _NONE), "horizon": (int, _NONE), "horizon_source": (str, _NONE),
    "duration_s": (float, int), "attempts": (int,), "error_kind": (str, _NONE), "output_errors": (list,),
    "extra": (dict,),
}


def record_problem(data: Any) -> str | None:
    """What is wrong with one ``episodes.jsonl`` record (``None``: nothing), naming the field."""
    if not isinstance(data, dict):
        return "not a JSON object"
    for key, types in (*_RECORD_TYPES.items(), *_OPTIONAL_TYPES.items()):
        if key not in data:
            if key in _RECORD_TYPES:
                return f"field {key!r} is missing"
            continue
        value = data[key]
        if not isinstance(value, types) or (isinstance(value, bool) and bool not in types):
            return f"field {key!r} is {json.dumps(value)[:40]}"
    return None


def read_episodes(path: Path, torn_tail: bool = False) -> list[EpisodeResult]:
    """The episodes of ``episodes.jsonl`` in file order, each record checked (:func:`record_problem`);
    a bad record or an episode recorded twice is a :class:`RunFileError` naming the file, line and
    field. ``torn_tail``: a last line without its newline (killed mid-write) is dropped instead."""
    if not path.is_file():
        raise RunFileError(f"{path}: missing")
    text = path.read_text(errors="replace")
    lines = text.splitlines()
    done: dict[int, EpisodeResult] = {}
    first_line: dict[int, int] = {}
    for lineno, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            data = json.loads(line)
        except (json.JSONDecodeError, RecursionError) as exc:
            if torn_tail and lineno == len(lines) and not text.endswith("\n"):
                continue
            why = f"not valid JSON: {exc}" if isinstance(exc, json.JSONDecodeError) else "JSON nested too deeply"
            raise RunFileError(f"{path}:{lineno}: corrupt episode record ({why})") from None
        problem = record_problem(data)
        if problem:
            raise RunFileError(f"{path}:{lineno}: corrupt episode record ({problem})")
        r = EpisodeResult.from_dict(data)
        if r.episode_index in done:
            raise RunFileError(f"{path}:{lineno}: episode {r.episode_index} is recorded twice (also line "
                               f"{first_line[r.episode_index]})")
        done[r.episode_index], first_line[r.episode_index] = r, lineno
    return list(done.values())


def wilson_ci(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval (scipy's) for k successes in n trials at ``z`` (``(0, 1)`` when n == 0)."""
    if n == 0:
        return (0.0, 1.0)
    from scipy.stats import binomtest, norm  # lazily: workers import this module, not scipy.stats

    ci = binomtest(k, n).proportion_ci(confidence_level=1 - 2 * norm.sf(z), method="wilson")
    return (float(ci.low), float(ci.high))


class _Part(BaseModel):
    """A part of ``results.json``: strict JSON types, no unknown field, never edited in place."""

    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)


class RobotRef(_Part):
    """A robot that ran: its name, version (the distribution that provides it) and the sha256 of its model
    as built (``null`` for an env suite's robot, which its env builds)."""

    name: str
    version: str | None = None
    sha256: str | None = None


class Rates(_Part):
    """One score block: the run's (the top of ``results.json``) or one task's (``per_task``)."""

    success_rate: float | None  # null: no episode of the block simulated
    success_once_rate: float | None
    n_episodes: int
    n_valid: int | None = None  # absent from runs written before it was counted
    n_success: int
    n_success_once: int
    n_errors: int
    ci95: tuple[float, float] | None  # Wilson 95 % interval of success_rate
    success_once_ci95: tuple[float, float] | None
    #: the mean over the block's episodes that simulated of each one's summed and best per-step reward
    #: (``lerobot-eval``'s ``avg_sum_reward``, ``avg_max_reward``); absent from runs written before them
    avg_sum_reward: float | None = None
    avg_max_reward: float | None = None
    robots: list[RobotRef] | None = None  # the robots its episodes ran (absent: written before version 2)

    @staticmethod
    def score(results: list[EpisodeResult]) -> dict[str, Any]:
        """The block's fields for ``results``: errors count as failures; rewards average the episodes that
        have them (every episode that simulated)."""
        n = len(results)
        k = sum(r.success for r in results)
        k_once = sum(r.success_once for r in results)
        n_errors = sum(r.error is not None for r in results)
        scored = n > n_errors  # at least one episode simulated
        rewarded = [r.extra for r in results if "max_reward" in r.extra]
        return {
            "success_rate": k / n if scored else None, "success_once_rate": k_once / n if scored else None,
            "n_episodes": n, "n_valid": n - n_errors, "n_success": k, "n_success_once": k_once,
            "n_errors": n_errors, "ci95": wilson_ci(k, n) if scored else None,
            "success_once_ci95": wilson_ci(k_once, n) if scored else None,
            **({f"avg_{key}": sum(float(e[key]) for e in rewarded) / len(rewarded)
                for key in ("sum_reward", "max_reward")} if rewarded else {}),
        }


class TaskRates(Rates):
    """One task's score block (``per_task``), with the task's instructions."""

    #: the prompts of the task's episodes, each once, in episode order (an env suite's task has one);
    #: absent from runs written before them
    instructions: list[str] | None = None


class EpisodeError(_Part):
    episode_index: int
    error: str
    error_kind: str | None = None  # absent from runs written before errors had a kind


class StartWarnings(_Part):
    episode_index: int
    warnings: list[str]


class ParityNotes(_Part):
    """Why the other ``task_rules`` would have judged this episode otherwise (Task.parity_notes)."""

    episode_index: int
    notes: list[str]


class OutputErrors(_Part):
    episode_index: int
    errors: list[str]


class BenchmarkRef(_Part):
    """Which benchmark ran: its name, content hash, size and where it was read."""

    name: str
    sha256: str | None = None
    n_episodes: int | None = None
    path: str | None = None


class Push(_Part):
    """``push``: where ``push=true`` uploaded the dataset, and whether it worked (a failed push keeps
    every local file and fails the run)."""

    key: ClassVar[str] = "push"
    repo_id: str
    ok: bool
    error: str | None


#: what a step after the score adds to ``results.json`` (its ``key`` names the field)
SummaryPiece = Push


class RunSummary(Rates):
    """``results.json``: the run's score, per task, its errors, and what the run was.

    The fields below the score say what was run (as ``run.json``) and how; a field a run did not
    record (an older run, a partial summary in a test) is absent, not ``null``, when written back.
    Unknown top-level fields of an existing file are kept as they are."""

    model_config = ConfigDict(strict=True, extra="allow", frozen=True)

    schema_version: int = 1  # a file without it: written before it existed (summarize writes SCHEMA_VERSION)
    primary_metric: str = PRIMARY_METRIC
    per_task: dict[str, TaskRates]
    errors: list[EpisodeError]
    start_warnings: list[StartWarnings] | None = None  # episodes that started oddly (Task.start_warnings)
    parity_notes: list[ParityNotes] | None = None  # episodes the other task_rules would judge otherwise
    output_errors: list[OutputErrors] | None = None
    # what the run was (run.json)
    benchmark: BenchmarkRef | None = None
    policy: dict[str, Any] | None = None
    policy_checkpoint: dict[str, Any] | None = None
    seed: int | None = None
    limit: int | None = None
    horizon: int | None = None
    timing: dict[str, Any] | None = None
    mujoco: str | None = None
    code: dict[str, Any] | None = None
    render_profile: dict[str, Any] | None = None
    recording: dict[str, Any] | None = None
    eval_options: dict[str, Any] | None = None
    selection: dict[str, Any] | None = None
    # how it ran
    thresholds: dict[str, dict[str, Any]] | None = None
    versions: dict[str, str] | None = None
    workers: int | None = None
    executor: str | None = None
    output_dir: str | None = None
    started_at: str | None = None
    wall_time_s: float | None = None
    config: dict[str, Any] | None = None
    startup: dict[str, Any] | None = None
    # after the score
    push: Push | None = None
    export_errors: list[str] | None = None

    def with_piece(self, piece: SummaryPiece) -> RunSummary:
        """This summary with what a step after the score returned."""
        return self.model_copy(update={piece.key: piece})

    def document(self) -> dict[str, Any]:
        """The JSON document (``results.json``'s content), its version and primary metric first."""
        doc = self.model_dump(mode="json", exclude_unset=True)
        return {**{k: doc.pop(k) for k in ("schema_version", "primary_metric") if k in doc}, **doc}

    def to_json(self) -> str:
        return json.dumps(self.document(), indent=2) + "\n"

    @classmethod
    def from_document(cls, data: Any, where: str = "results.json") -> RunSummary:
        """Validate a parsed ``results.json``; a :class:`RunFileError` names ``where`` and the first bad field."""
        if not isinstance(data, dict):
            raise RunFileError(f"{where}: expected a JSON object")
        version = data.get("schema_version", 1)
        if isinstance(version, int) and not isinstance(version, bool) and version > SCHEMA_VERSION:
            raise RunFileError(f"{where}: schema_version {version} is newer than this molmo-lerobot reads "
                               f"({SCHEMA_VERSION}); read it with the version that wrote it")
        try:
            return cls.model_validate_json(json.dumps(data))  # JSON mode: arrays are tuples, nothing coerced
        except ValidationError as exc:
            first = exc.errors()[0]
            loc = ".".join(str(p) for p in first["loc"])
            value = "" if first["type"] == "missing" else f" ({json.dumps(first['input'], default=str)[:40]})"
            raise RunFileError(f"{where}: field {loc}: {first['msg']}{value}") from None

    @classmethod
    def read(cls, path: Path) -> RunSummary:
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise RunFileError(f"{path}: not valid JSON ({exc})") from None
        except RecursionError:
            raise RunFileError(f"{path}: JSON nested too deeply") from None
        return cls.from_document(data, str(path))


def _instructions(results: list[EpisodeResult]) -> list[str]:
    return list(dict.fromkeys(r.prompt for r in results if r.prompt is not None))


def summarize(results: list[EpisodeResult], **context: Any) -> RunSummary:
    """The run's summary: overall and per-task scores of ``results`` plus ``context`` (the fields
    of :class:`RunSummary` below the score: ``benchmark``, ``policy``, …)."""
    unknown = sorted(set(context) - set(RunSummary.model_fields))
    if unknown:
        raise TypeError(f"summarize: no results.json field {', '.join(unknown)}")
    by_task: dict[str, list[EpisodeResult]] = defaultdict(list)
    for r in results:
        by_task[r.task_type or r.task_cls or "unknown"].append(r)
    return RunSummary.model_validate({
        "schema_version": SCHEMA_VERSION, "primary_metric": PRIMARY_METRIC, **Rates.score(results),
        "per_task": {t: {**Rates.score(rs), "instructions": _instructions(rs), **_robots(rs, context.get("robots"))}
                     for t, rs in sorted(by_task.items())},
        "errors": [{"episode_index": r.episode_index, "error": r.error, "error_kind": r.error_kind}
                   for r in results if r.error is not None],
        "start_warnings": [{"episode_index": r.episode_index, "warnings": r.extra["start_warnings"]}
                           for r in results if r.extra.get("start_warnings")],
        "parity_notes": [{"episode_index": r.episode_index, "notes": r.extra["parity_notes"]}
                         for r in results if r.extra.get("parity_notes")],
        "output_errors": [{"episode_index": r.episode_index, "errors": r.output_errors}
                          for r in results if r.output_errors],
        **context,
    }, strict=False)


def _robots(results: list[EpisodeResult], robots: list[dict[str, Any]] | None) -> dict[str, Any]:
    """``{"robots": [...]}``: those of ``robots`` (the run's) that ``results`` ran (their ``extra.robot``)."""
    if robots is None:
        return {}
    ran = {r.extra.get("robot") for r in results}
    return {"robots": [robot for robot in robots if robot["name"] in ran]}


def summary_lines(s: RunSummary, max_errors: int = 10) -> list[str]:
    """The run's headline, per-task lines and first errors, for a terminal.

    A run with errors leads with their count; one in which no episode simulated says
    "no episode ran" instead of a score.
    """
    head = f"{s.benchmark.name if s.benchmark else '?'} · {(s.policy or {}).get('name', '?')}"
    errors = f"{s.n_errors} of {s.n_episodes} episodes errored"
    if s.success_rate is None or s.ci95 is None or s.success_once_rate is None:
        lines = [f"no episode ran: {errors} · {head}: no score"]
    else:
        lo, hi = s.ci95
        lines = [f"{errors + ' · ' if s.n_errors else ''}{head}: success {s.success_rate:.3f} "
                 f"[{lo:.3f}, {hi:.3f}] ({s.n_success}/{s.n_episodes}), "
                 f"{SUCCESS_LABELS['success_once']} {s.success_once_rate:.3f}{_reward_text(s)}"]
        for task, b in s.per_task.items():
            rate = "no episode ran" if b.success_rate is None else f"{b.success_rate:.3f}"
            tail = f", {b.n_errors} errored" if b.n_errors else ""
            lines.append(f"  {task}: {rate} ({b.n_success}/{b.n_episodes}{tail}){_reward_text(b)}")
    lines.extend(f"  episode {e.episode_index}: {e.error}" for e in s.errors[:max_errors])
    if len(s.errors) > max_errors:
        lines.append(f"  ... and {len(s.errors) - max_errors} more errors (results.json)")
    n_infra = sum(e.error_kind == INFRASTRUCTURE for e in s.errors)
    if n_infra:
        lines.append(f"  {n_infra} of the errors are infrastructure failures (worker, disk, policy server): "
                     "fix the cause and rerun with resume=true to run those episodes again")
    notes = s.parity_notes or []
    if notes:
        lines.append(f"  {len(notes)} episode{'s' * (len(notes) != 1)} judged otherwise by the other task_rules "
                     f"(episode {notes[0].episode_index}: {notes[0].notes[0]}; all in results.json parity_notes)")
    outputs = s.output_errors or []
    if outputs:
        first = outputs[0]
        lines.append(f"  outputs not written for {len(outputs)} episode{'s' * (len(outputs) != 1)}, outcomes kept "
                     f"(episode {first.episode_index}: {first.errors[0]}; all in results.json output_errors)")
    return lines


def _reward_text(block: Rates) -> str:
    return "" if block.avg_max_reward is None else f", avg max reward {block.avg_max_reward:.3f}"


@dataclass(frozen=True)
class RecordedRun:
    """A run directory as read back: its summary (``None``: no ``results.json``, the run is unfinished)
    and its episodes (``episodes.jsonl``, in file order)."""

    path: Path
    summary: RunSummary | None
    episodes: list[EpisodeResult]


def read_run(path: str | Path, finished: bool = True) -> RecordedRun:
    """Read the run in ``path``: ``results.json`` and ``episodes.jsonl``, every record checked; anything
    wrong is one :class:`RunFileError` line naming the file (and line) and field. ``finished=False``
    reads a run being resumed: its episodes only (a missing file: none yet; a torn last line, killed
    mid-write, is dropped), not its ``results.json``, which the resume replaces."""
    root = Path(path)
    if not root.is_dir():
        raise RunFileError(f"{root}: not a run directory")
    episodes_file = root / EPISODES_FILE
    if not finished:
        return RecordedRun(root, None, read_episodes(episodes_file, torn_tail=True) if episodes_file.exists() else [])
    results = root / RESULTS_FILE
    if not results.exists():
        raise RunFileError(f"{root}: no {RESULTS_FILE} (unfinished run? complete it with resume=true)")
    return RecordedRun(root, RunSummary.read(results), read_episodes(episodes_file))
