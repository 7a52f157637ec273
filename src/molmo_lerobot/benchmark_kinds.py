"""What a benchmark kind is: the plugin contract every benchmark ``molmo-eval`` runs goes through.

A *benchmark kind* (:class:`BenchmarkKind`, provided by the ``molmo_benchmark_kinds`` hook) claims benchmark
names and turns one into a run: its typed options (``benchmark.<key>=``, :attr:`BenchmarkKind.options`), its
episodes planned (:class:`RunPlan`, one :class:`~molmo_lerobot.episode_plan.EpisodePlan` each), and, in each
worker, the :class:`Session` that plays a plan (:class:`EpisodeSessions`). Our own episode files (``pick_v1``, a
directory, a MolmoSpaces JSON) are the kind ``episodes``; LeRobot's env suites (LIBERO, PushT) are kinds of
their own; a third-party distribution adds one the same way. :func:`benchmark_kind` finds the kind of a
benchmark as pluggy's ``firstresult`` hooks do: the first kind in call order that claims the name (``episodes``
is ``trylast``: it claims every registered benchmark directory and every path).
"""

from __future__ import annotations

import difflib
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from pydantic import BaseModel, ConfigDict, ValidationError

from molmo_lerobot.errors import MolmoError

if TYPE_CHECKING:
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.dataset_layout import DatasetLayout
    from molmo_lerobot.episode_plan import EpisodePlan
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.policies.base import Action, Observation, Policy
    from molmo_lerobot.recording import EpisodeInfo
    from molmo_lerobot.results import EpisodeResult
    from molmo_lerobot.run_config import RunConfig


class BenchmarkKindError(MolmoError, ValueError):
    """A benchmark no kind claims, options its kind refuses, or a run its kind cannot do; one line naming the key."""


class BenchmarkOptions(BaseModel):
    """``benchmark.*``: the options every kind has (its name; ``path``, a directory or file of episodes). A kind
    subclasses it with its own fields and defaults (stated once, there); an unknown key is refused."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    path: str | None = None


class Session(Protocol):
    """One planned episode, open: what the rollout loop and the worker read and call. Our scenes'
    (:class:`~molmo_lerobot.runner.episode.EpisodeSession`) and each env suite's implement it."""

    plan: EpisodePlan
    steps: int
    #: the last step's reward as the task defines it (None: it defines none); what recorders get
    task_reward: float | None

    @property
    def horizon(self) -> int: ...

    @property
    def move_groups(self) -> dict[str, int]:
        """Each move group's action size (what a policy's action is checked against)."""

    @property
    def renderer_setup_s(self) -> float:
        """Seconds its renderers took to create (the worker's start-up report)."""

    def observe(self, images: bool = True) -> Observation: ...

    def complete(self, action: Action) -> Action: ...

    def step(self, action: Action, *, observed: bool = True, images: bool = True) -> bool: ...

    def end(self, said_done: bool = False) -> str | None: ...

    def result(self) -> EpisodeResult: ...

    def recorder_info(self, *, expert: bool, extra: dict[str, Any]) -> EpisodeInfo: ...

    def close(self) -> None: ...


class EpisodeSessions(ABC):
    """A worker's opener of sessions for one run (what it keeps across episodes: an env suite's process)."""

    @abstractmethod
    def open(self, plan: EpisodePlan, policy: Policy | None, *, environment_state: str | None,
             end_on_success: bool) -> Session:
        """``plan`` open, ``policy`` reset for it; ``environment_state``: who asks observations to carry the
        task's environment state (None: no one)."""

    def close(self) -> None:  # noqa: B027  # most openers keep nothing
        """Release what the opener keeps (called once, when the worker stops)."""


class BenchmarkEpisodes(Protocol):
    """A loaded benchmark as the run directory, the selection and the summary read it."""

    @property
    def name(self) -> str: ...

    @property
    def episodes(self) -> Sequence[Any]: ...

    @property
    def sha256(self) -> str: ...

    @property
    def path(self) -> Path: ...

    @property
    def origins(self) -> Sequence[Any]: ...

    def where(self, index: int) -> str: ...


@dataclass(frozen=True)
class Listing:
    """One benchmark as ``molmo-bench list`` shows it."""

    #: what it is (``directory``, ``env suite libero``)
    kind: str
    episodes: str
    horizon: str
    where: str


@dataclass
class RunPlan:
    """A run's episodes planned: one plan per selected index, and what ``results.json`` reports of them."""

    plans: dict[int, EpisodePlan]
    #: each task type's thresholds and horizons (``results.json``'s ``thresholds``)
    thresholds: dict[str, Any] = field(default_factory=dict)
    #: the run's horizons per task type in seconds (``run.json``'s ``eval_options.horizons``)
    horizons: dict[str, float] = field(default_factory=dict)


class BenchmarkKind[OptionsT: BenchmarkOptions](ABC):
    """A kind of benchmark (see the module docstring). Subclasses set :attr:`name` and :attr:`options` and
    implement the abstract methods; what they refuse they raise as :class:`BenchmarkKindError`."""

    name: str
    aliases: tuple[str, ...] = ()
    description: str = ""
    #: the model of its ``benchmark.*`` options
    options: type[OptionsT]

    @abstractmethod
    def benchmarks(self, plugins: Plugins) -> dict[str, Listing]:
        """Each benchmark name it runs (``benchmark=<name>``) as ``molmo-bench list`` shows it."""

    def claims(self, name: str, path: str | None, plugins: Plugins) -> bool:
        """Whether it runs ``benchmark.name=name`` (``benchmark.path=path``)."""
        return path is None and name in self.benchmarks(plugins)

    def config_node(self, name: str) -> dict[str, Any]:
        """``benchmark/<name>``'s Hydra node: its options at their defaults."""
        return self.options.model_validate({"name": name}).model_dump(mode="json")

    def options_of(self, config: RunConfig) -> OptionsT:
        """``config.benchmark`` as its options; one :class:`BenchmarkKindError` line naming the first bad key."""
        given = config.benchmark.model_dump()
        try:
            return self.options.model_validate(given)
        except ValidationError as exc:
            raise BenchmarkKindError(_option_message(exc, given, self)) from None

    def check_run(self, config: RunConfig) -> None:  # noqa: B027  # most kinds honour every run option
        """Refuse (:class:`BenchmarkKindError`) the run options this kind cannot honour, before any output."""

    @abstractmethod
    def load(self, run: RunContext) -> tuple[BenchmarkEpisodes, RunContext]:
        """The run's benchmark, and the run context as the benchmark decides it (its render profile, whether
        its episodes sleep)."""

    @abstractmethod
    def plan(self, run: RunContext, bench: BenchmarkEpisodes, indices: list[int]) -> RunPlan:
        """Episodes ``indices`` of ``bench`` planned; the run checked to be playable here."""

    @abstractmethod
    def sessions(self, run: RunContext) -> EpisodeSessions:
        """A worker's opener of this run's sessions."""

    def run_options(self, config: RunConfig) -> dict[str, Any]:
        """What of its options ``run.json`` records under ``eval_options`` (a resume must match it)."""
        return {}

    def recording_layout(self, config: RunConfig) -> DatasetLayout | None:
        """The dataset schema ``record=true`` writes (a suite's published datasets'); None: each recording's
        schema follows its first step."""
        return None

    def robot(self, plan: EpisodePlan) -> str | None:
        """The robot ``plan`` runs (None: none)."""
        return None

    def robots(self, run: RunContext, plans: dict[int, EpisodePlan]) -> list[dict[str, Any]]:
        """``run.json``'s ``robots``: each robot the plans run, its name (its version and model hash where the
        kind builds it)."""
        names = sorted({robot for plan in plans.values() if (robot := self.robot(plan)) is not None})
        return [{"name": name, "version": None, "sha256": None} for name in names]

    def validate(self, config: RunConfig) -> tuple[list[str], list[str]]:
        """``molmo-bench validate``: the benchmark of ``config`` planned and checked, as ``(report lines,
        problems)`` (a problem: one line naming the episode and field)."""
        return ["checked    options only: its episodes are checked when a run plans them"], []

    def about(self, plugins: Plugins) -> list[str]:
        """Lines ``molmo-bench list`` prints under the table (where its env and assets come from)."""
        return []


def _option_message(exc: ValidationError, given: dict[str, Any], kind: BenchmarkKind[Any]) -> str:
    error = exc.errors()[0]
    key = ".".join(str(p) for p in error["loc"]) or "benchmark"
    if error["type"] == "extra_forbidden":
        fields = [f for f in kind.options.model_fields if f not in ("name", "path")]
        close = difflib.get_close_matches(key, fields, n=1)
        hint = f"; did you mean benchmark.{close[0]}?" if close else ""
        return (f"benchmark.{key}: not an option of {kind.name} benchmarks (benchmark={given.get('name')}){hint} "
                f"(options: {', '.join(fields) or 'none'})")
    field = kind.options.model_fields.get(str(error["loc"][0])) if error["loc"] else None
    default = f"; default {field.default!r}" if field is not None and not field.is_required() else ""
    return f"benchmark.{key}: {error['msg']}, got {error.get('input')!r} (benchmark={given.get('name')}{default})"


def benchmark_kinds(plugins: Plugins) -> list[BenchmarkKind[Any]]:
    """Every benchmark kind, in pluggy's call order (the order they are asked to claim a name)."""
    return [kind for kind, _ in plugins.provided("benchmark_kind")]


def benchmark_kind(plugins: Plugins, name: str, path: str | None = None) -> BenchmarkKind[Any]:
    """The kind that runs ``benchmark.name=name`` (``benchmark.path=path``): the first that claims it."""
    kinds = benchmark_kinds(plugins)
    for kind in kinds:
        if kind.claims(name, path, plugins):
            return kind
    known = sorted({n for kind in kinds for n in kind.benchmarks(plugins)})
    close = difflib.get_close_matches(name, known, n=3)
    hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
    raise BenchmarkKindError(f"benchmark={name}: no benchmark of that name and no such directory or file{hint} "
                             f"(molmo-bench list shows every benchmark)")


def run_kind(plugins: Plugins, config: RunConfig) -> BenchmarkKind[Any]:
    """The kind of ``config``'s benchmark."""
    bench = config.benchmark.model_dump()
    return benchmark_kind(plugins, str(bench["name"]), bench.get("path"))
