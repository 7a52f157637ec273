"""Env-suite benchmarks as a benchmark kind: ``molmo-eval benchmark=libero_object`` and its kin, ``benchmark=pusht``.

An env suite (LeRobot's LIBERO, PushT) is described by one :class:`SuiteKind` (its episode type and planner, its
env, its policy interface, its typed options) and runs as an :class:`EnvSuiteKind`, the
:class:`~molmo_lerobot.benchmark_kinds.BenchmarkKind` that :mod:`molmo_lerobot.suites.plugin` registers for it.
Its benchmarks' episodes are the suite's own episode specs (planned in ``lerobot-eval``'s order and seeding from
the suite's task catalogue), not MolmoSpaces episode files; each becomes an
:class:`~molmo_lerobot.episode_plan.EpisodePlan` of its kind (spec: the episode's fields; seed and digest: the
episode's), so workers, executors, resume, ``results.json`` (one ``per_task`` row per task), ``episodes.jsonl``,
compare and report are the same code as for our benchmarks. A worker plays a suite plan in a
:class:`SuiteSession` on its own suite (LIBERO's process, PushT's env), started at its first episode and kept
across episodes (:class:`SuiteSessions`).

Options (``benchmark.<key>=``, :class:`SuiteOptions` and each suite's subclass): ``episodes_per_task``
(``lerobot-eval``'s ``--eval.n_episodes``), ``image_size`` (camera images, default LeRobot's; at most
:data:`MAX_IMAGE_SIZE`), and a suite's own (LIBERO's ``hard_reset``).
"""

from __future__ import annotations

import contextlib
import importlib.metadata as md
import sys
from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
from pydantic import Field

from molmo_lerobot.benchmark_kinds import (
    BenchmarkKind,
    BenchmarkKindError,
    BenchmarkOptions,
    EpisodeSessions,
    Listing,
    RunPlan,
)
from molmo_lerobot.episode_plan import EpisodePlan
from molmo_lerobot.errors import InfrastructureError, describe
from molmo_lerobot.hashing import content_sha256
from molmo_lerobot.results import EpisodeOutcome
from molmo_lerobot.suites.pipe import SuiteError

if TYPE_CHECKING:
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.dataset_layout import DatasetLayout
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyType
    from molmo_lerobot.recording import EpisodeInfo
    from molmo_lerobot.results import EpisodeResult
    from molmo_lerobot.run_config import RunConfig

#: the largest ``benchmark.image_size``: the side of the largest frames drawn (LIBERO draws 4096², its offscreen
#: buffer grown to fit; a side beyond that can exceed the GL renderbuffer limit)
MAX_IMAGE_SIZE = 4096


#: a camera image's side in pixels
ImageSize = Annotated[int, Field(ge=1, le=MAX_IMAGE_SIZE)]


class SuiteOptions(BenchmarkOptions):
    """The options of every env-suite benchmark; a suite's subclass adds its own (``image_size: ImageSize`` where
    its frames' side is an option, with LeRobot's default)."""

    #: episodes per task (``lerobot-eval``'s ``--eval.n_episodes``): episode ``k`` of a task, seed ``seed + k``
    episodes_per_task: int = Field(1, ge=1)


@dataclass(frozen=True)
class SuiteKind[OptionsT: SuiteOptions]:
    """What one env suite brings: its episode type and planner, its env (``open(options)``: an object with
    ``tasks``, ``reset``, ``step``, ``close`` and ``alive``), its policy interface and its options."""

    #: the kind's name (``results.json``'s plans carry it; ``molmo-plugins`` lists it)
    name: str
    episode: type[Any]
    plan: Callable[..., list[Any]]
    open: Callable[[OptionsT], Any]
    task_label: Callable[[Any], str]
    observation: Callable[[Any, int], Observation]
    move_group: str
    action_dim: int
    control_hz: float
    #: our camera -> the feature LeRobot's env hands a policy its frames as (``preprocess_observation``'s name)
    cameras: dict[str, str]
    #: its frames' side (``options.image_size``), or (height, width) where they are fixed and not square (ALOHA's)
    frame_size: Callable[[OptionsT], int | tuple[int, int]]
    options: type[OptionsT]
    #: what the policy learns of the action (``EpisodeContext.extra``): ``delta_groups`` (LIBERO's delta-EEF
    #: command) or ``action_bounds`` (PushT's target position, within the workspace)
    action_extra: dict[str, Any]
    #: its benchmarks (``benchmark=<name>``) and LeRobot's step limit of each (the default horizon)
    benchmarks: dict[str, int]
    #: the problems of one planned episode against the suite's task catalogue (``[]``: none)
    check_episode: Callable[[Any, list[dict[str, Any]]], list[str]]
    #: the distributions its env and assets come from (``molmo-bench list`` shows their version and licence)
    distributions: tuple[str, ...]
    #: the site-packages directories those distributions live in besides this venv's (LIBERO's venv)
    site_packages: Callable[[], list[str]] = list
    #: the dataset layout ``record=true`` writes (``recording(options)``: the schema of the suite's LeRobot
    #: datasets, ``lerobot/libero``'s, ``lerobot/pusht``'s); None: ``record=true`` is refused
    recording: Callable[[OptionsT], DatasetLayout] | None = None
    #: the robot its env builds (its datasets' ``robot_type``); None: none (PushT's pusher)
    robot: str | None = None
    #: a fault of the installed files its env reads in place (one line naming the file and what to reinstall),
    #: or None: checked before any worker starts, and after an episode failed (then the machine's failure)
    install_problem: Callable[[], str | None] | None = None
    #: how to install the suite, said where a distribution is missing (``make .libero-venv``)
    remedy: str = ""

    def problem(self) -> str | None:
        """What is broken in the suite's installed files, or None."""
        return self.install_problem() if self.install_problem is not None else None


class EnvSuiteKind[OptionsT: SuiteOptions](BenchmarkKind[OptionsT]):
    """The benchmark kind of one env suite: its benchmarks planned from the task catalogue its own env lists."""

    def __init__(self, suite: SuiteKind[OptionsT]) -> None:
        self.suite = suite
        self.name = suite.name
        self.options = suite.options
        source = f", from {suite.distributions[0]}" if suite.distributions else ""
        self.description = f"env suite {suite.name}{source}"

    def benchmarks(self, plugins: Plugins) -> dict[str, Listing]:
        per_task = self.suite.options.model_fields["episodes_per_task"].default
        return {name: Listing(f"env suite {self.name}", f"{per_task} per task", f"{steps} (the suite's)",
                              f"{self.name}:{name}") for name, steps in self.suite.benchmarks.items()}

    def check_run(self, config: RunConfig) -> None:
        name = config.benchmark.name
        if config.record_environment_state:
            raise BenchmarkKindError(f"record_environment_state: env-suite episodes (benchmark={name}) have no "
                                     "environment state; their recording has the suite's own dataset layout")
        if config.robot.name is not None:
            raise BenchmarkKindError(f"robot.name: env-suite episodes (benchmark={name}) run the robot their env "
                                     "builds; leave robot.name out")
        if config.sample is not None:
            raise BenchmarkKindError(f"sample: not available for env-suite benchmarks (benchmark={name}); use "
                                     "limit= or episodes=")
        if config.record and self.suite.recording is None:
            raise BenchmarkKindError(f"record=true: env suite {self.name!r} (benchmark={name}) has no recording "
                                     "layout; run without record")
        self.options_of(config)

    def load(self, run: RunContext) -> tuple[SuiteBenchmark, RunContext]:
        """:meth:`benchmark_of` the run; not our physics: ``timing.sleep`` is recorded as given, unset false."""
        return self.benchmark_of(run.config), run.with_sleep(bool(run.config.timing.sleep))

    def benchmark_of(self, config: RunConfig) -> SuiteBenchmark:
        """The suite's episodes for ``config``: its installed files checked (:class:`~molmo_lerobot.errors.
        InfrastructureError` naming the first broken one), its task catalogue (read from the suite's env), then
        ``episodes_per_task`` episodes per task with the run's seed, ``horizon`` overriding LeRobot's step
        limit."""
        problem = self.suite.problem()
        if problem:
            raise InfrastructureError(f"cannot run benchmark={config.benchmark.name}: {problem}")
        return self.plan_benchmark(config, self.tasks(config))

    def tasks(self, config: RunConfig) -> list[dict[str, Any]]:
        """The task catalogue of the run's benchmark, as the suite's own env lists it (LIBERO: its process in
        the LIBERO venv; PushT: gym_pusht's one task)."""
        env = self.suite.open(self.options_of(config))
        try:
            return env.tasks(str(config.benchmark.name))
        finally:
            env.close()

    def plan_benchmark(self, config: RunConfig, tasks: list[dict[str, Any]]) -> SuiteBenchmark:
        """The run's episodes of the benchmark whose task catalogue is ``tasks``."""
        name = str(config.benchmark.name)
        episodes = self.suite.plan(name, tasks, self.options_of(config).episodes_per_task, seed=config.seed,
                                   horizon=config.horizon)
        return SuiteBenchmark(name, episodes, Path(f"{self.name}:{name}"), self.suite)

    def plan(self, run: RunContext, bench: Any, indices: list[int]) -> RunPlan:
        cli = run.config.horizon is not None
        return RunPlan({i: suite_plan(i, self.suite, bench.episodes[i], cli) for i in indices})

    def sessions(self, run: RunContext) -> SuiteSessions:
        return self.sessions_of(run.config, run.plugins)

    def sessions_of(self, config: RunConfig, plugins: Plugins | None = None) -> SuiteSessions:
        """A worker's opener of ``config``'s sessions (what :meth:`sessions` gives; no run context needed), its
        experts from ``plugins`` (None: the installed ones)."""
        from molmo_lerobot.plugins import Plugins

        return SuiteSessions(self.suite, self.options_of(config), plugins or Plugins())

    def run_options(self, config: RunConfig) -> dict[str, Any]:
        """The suite's options (they change its frames, ``image_size``, or its episodes)."""
        return {"benchmark": self.options_of(config).model_dump(exclude={"name", "path"})}

    def recording_layout(self, config: RunConfig) -> DatasetLayout | None:
        return self.suite.recording(self.options_of(config)) if self.suite.recording is not None else None

    def robot(self, plan: EpisodePlan) -> str | None:
        return self.suite.robot

    def about(self, plugins: Plugins) -> list[str]:
        """The suite's distributions, each with its version and licence as installed."""
        path = [*self.suite.site_packages(), *sys.path]
        out = []
        for name in self.suite.distributions:
            found = next(iter(md.distributions(name=name, path=path)), None)
            if found is None:
                out.append(f"{name} (not installed{'; ' + self.suite.remedy if self.suite.remedy else ''})")
                continue
            meta = found.metadata
            licence = meta.get("License-Expression") or meta.get("License") or "licence not declared"
            out.append(f"{name} {found.version} ({licence})")
        return [f"env suite {self.name}: " + ", ".join(out)]

    def validate(self, config: RunConfig) -> tuple[list[str], list[str]]:
        """The benchmark planned against the task catalogue the suite's own env lists, and its problems."""
        tasks = self.tasks(config)
        bench = self.plan_benchmark(config, tasks)
        problems = plan_problems(bench, tasks)
        if problems:
            return [], problems
        labels = Counter(self.suite.task_label(e) for e in bench.episodes)
        shown = list(labels.items())
        per_task = self.options_of(config).episodes_per_task
        return [f"episodes   {len(bench.episodes)} over {len(tasks)} tasks ({per_task} per task, seed {config.seed})",
                "tasks      " + ", ".join(f"{k} ({v})" for k, v in shown[:12]) + (", ..." if len(shown) > 12 else ""),
                f"horizon    {', '.join(map(str, sorted({e.horizon for e in bench.episodes})))} (LeRobot's step "
                f"limit {self.suite.benchmarks[bench.name]})",
                f"sha256     {bench.sha256}",
                "checked    options and episode plan against the suite's task catalogue: ok"], []


@dataclass(frozen=True)
class Origin:
    file: str


@dataclass
class SuiteBenchmark:
    """A suite's episodes for one run: what the run directory, selection and summary read of a benchmark."""

    name: str
    episodes: list[Any]
    path: Path
    #: the env suite it is a benchmark of
    suite: SuiteKind[Any]

    @property
    def sha256(self) -> str:
        """SHA-256 of the episodes' digests in order: the benchmark's identity (a resume must match it)."""
        return content_sha256([e.digest for e in self.episodes], ensure_ascii=True).hex()

    @property
    def origins(self) -> list[Origin]:
        return []

    def where(self, index: int) -> str:
        return f"{self.name} episode {index}"


def plan_problems(bench: SuiteBenchmark, tasks: list[dict[str, Any]]) -> list[str]:
    """What is wrong with ``bench``'s episodes against the suite's task catalogue ``tasks``, one line each
    naming the episode and field: the episode type and suite, a seed and a horizon >= 1, the suite's own checks
    (LIBERO: a task id of the catalogue, an init-state index within that task's init states, its instruction;
    PushT: its task), and no episode twice."""
    kind = bench.suite
    if bench.name not in kind.benchmarks:
        return [f"{bench.name}: not a benchmark of env suite {kind.name!r} ({', '.join(kind.benchmarks)})"]
    out: list[str] = []
    seen: dict[str, int] = {}
    for i, episode in enumerate(bench.episodes):
        where = bench.where(i)
        if not isinstance(episode, kind.episode):
            out.append(f"{where}: a {type(episode).__name__}, expected a {kind.episode.__name__}")
            continue
        found = [] if episode.suite == bench.name else [f"suite {episode.suite!r}: expected {bench.name!r}"]
        for field in ("seed", "horizon"):
            value = getattr(episode, field)
            if not isinstance(value, int) or isinstance(value, bool) or (field == "horizon" and value < 1):
                found.append(f"{field} {value!r}: expected an integer" + " >= 1" * (field == "horizon"))
        found += kind.check_episode(episode, tasks)
        if episode.digest in seen:
            found.append(f"the same episode as episode {seen[episode.digest]}")
        seen.setdefault(episode.digest, i)
        out += [f"{where}: {problem}" for problem in found]
    return out


def suite_plan(index: int, suite: SuiteKind[Any], episode: Any, horizon_from_cli: bool) -> EpisodePlan:
    """Episode ``index`` of one of ``suite``'s benchmarks as a plan of its kind: its spec the episode's fields, its
    seed and digest the episode's own, its task the suite's label (``<suite>/task_<id>``)."""
    return EpisodePlan.of(index, asdict(episode), episode.seed, suite.task_label(episode), episode.instruction,
                          episode.horizon, "cli" if horizon_from_cli else "lerobot", episode.digest, kind=suite.name)


class SuiteSession(EpisodeOutcome):
    """One suite episode, open: the :class:`~molmo_lerobot.benchmark_kinds.Session` the rollout loop plays, over
    the worker's suite env. ``lerobot-eval``'s rules: the episode ends at its first terminated step (LIBERO's goal
    reached) or at the horizon; it succeeds when its last step did."""

    #: a suite env draws its frames in its own step: no renderer of ours to set up
    renderer_setup_s = 0.0

    def __init__(self, kind: SuiteKind[Any], plan: EpisodePlan, suite: Any, image_size: int | tuple[int, int],
                 end_on_success: bool) -> None:
        if plan.kind != kind.name:
            raise ValueError(f"episode {plan.episode_index}: a plan of kind {plan.kind!r}, not of env suite "
                             f"{kind.name!r}")
        self.kind, self.plan, self.suite, self.image_size = kind, plan, suite, image_size
        self.episode = kind.episode(**{f.name: plan.spec[f.name] for f in fields(kind.episode)})
        self.end_on_success = end_on_success
        super().__init__()
        self.terminated = False
        self._obs = suite.reset(self.episode)

    @property
    def horizon(self) -> int:
        return int(self.plan.horizon or 0)

    @property
    def move_groups(self) -> dict[str, int]:
        return {self.kind.move_group: self.kind.action_dim}

    def policy_context(self, expert: PolicyType | None = None) -> EpisodeContext:
        """What the policy learns at reset; ``expert`` (for a scripted policy, privileged): the expert registered
        for the episode's task type, and the suite's env as ``extra["suite"]``."""
        from molmo_lerobot.policies.base import EpisodeContext

        extra = {**self.kind.action_extra, "camera_features": dict(self.kind.cameras)}
        if expert is not None:
            extra["suite"] = self.suite
        return EpisodeContext.of_plan(self.plan, self.move_groups, 1.0 / self.kind.control_hz, expert=expert,
                                      extra=extra)

    def recorder_info(self, *, expert: bool, extra: dict[str, Any]) -> EpisodeInfo:
        from molmo_lerobot.recording import EpisodeInfo

        return EpisodeInfo(identity=self.plan.identity, fps=float(self.kind.control_hz),
                           camera_names=list(self.kind.cameras), img_resolution=self._resolution(),
                           joint_names={}, move_groups=self.move_groups, expert=expert,
                           extra={**self._suite_fields(), **extra})

    def _resolution(self) -> tuple[int, int]:
        """The frames' (width, height): ``image_size`` is their side, or their (height, width)."""
        size = self.image_size
        return (size, size) if isinstance(size, int) else (size[1], size[0])

    def observe(self, images: bool = True) -> Observation:
        """The observation now; ``images``: with the camera frames (the last step must have drawn them)."""
        obs = self.kind.observation({**self._obs, "task": self.plan.prompt}, self.steps)
        if not images:
            obs.pop("images", None)
        elif "images" not in obs:
            raise RuntimeError(f"{self.plan.identity}: images asked for at step {self.steps}, "
                               "but the step was played without them")
        return obs

    def complete(self, action: Action) -> Action:
        return action

    def step(self, action: Action, *, observed: bool = True, images: bool = True) -> bool:
        """One step of the suite's env; ``images``: the next :meth:`observe` asks for frames, so the step
        draws them (LIBERO draws inside its step; a frame nobody reads is not drawn)."""
        reply = self.suite.step(np.asarray(action[self.kind.move_group], dtype=np.float64), images=images)
        self._obs = reply["observation"]
        self.terminated = bool(reply["terminated"])
        return self.count_step(bool(reply["success"]), observed, float(reply["reward"]))

    def end(self, said_done: bool = False, terminated: bool = False) -> str | None:
        """As :meth:`EpisodeOutcome.end`, the suite's env ending the episode when it says ``terminated``."""
        return super().end(said_done, terminated or self.terminated)

    def result(self) -> EpisodeResult:
        from molmo_lerobot.results import EpisodeResult

        plan = self.plan
        return EpisodeResult(
            episode_index=plan.episode_index, house_index=None, task_cls=None, success=self.success,
            success_once=self.success_once, steps=self.steps, seed=plan.seed, task_type=plan.task_type,
            prompt=plan.prompt, horizon=self.horizon,
            extra={"ended_by": self.ended_by or "horizon", "end_on_success": self.end_on_success,
                   "success_any_step": self.success_any_step, **self.rewards(), **self._suite_fields(),
                   "digest": self.episode.digest})

    def _suite_fields(self) -> dict[str, Any]:
        """Which of the suite's episodes this is, minus what the result holds anyway (seed, horizon, prompt):
        LIBERO's suite, task id and init state; PushT's suite and task."""
        return {k: v for k, v in asdict(self.episode).items() if k not in ("seed", "horizon", "instruction")}

    def close(self) -> None:
        """Nothing: the suite env outlives the episode (:class:`SuiteSessions`)."""


class SuiteSessions(EpisodeSessions):
    """A worker's suite env (LIBERO's process, PushT's env), started at its first episode and kept until
    :meth:`close`; one whose process was lost is replaced at the next episode."""

    def __init__(self, kind: SuiteKind[Any], options: SuiteOptions, plugins: Plugins) -> None:
        self.kind, self.options, self.plugins = kind, options, plugins
        self._suite: Any = None

    def open(self, plan: EpisodePlan, policy: Policy | None, *, environment_state: str | None = None,
             end_on_success: bool = False) -> SuiteSession:
        """``plan`` opened on the worker's suite env, started now if it is not running (the first episode, or
        after the last one's process was lost: died, hung and killed)."""
        if environment_state:
            raise ValueError(f"env suite {self.kind.name!r} has no environment state (asked for by "
                             f"{environment_state})")
        if self._suite is not None and not self._suite.alive:
            self.close()
        if self._suite is None:
            self._suite = self.kind.open(self.options)
        try:
            session = SuiteSession(self.kind, plan, self._suite, self.kind.frame_size(self.options), end_on_success)
        except SuiteError as exc:  # the episode's, unless the suite's installed files are broken now
            problem = self.kind.problem() if not isinstance(exc, InfrastructureError) else None
            if problem:
                raise InfrastructureError(f"{problem} (the episode failed to start: {describe(exc)})") from exc
            raise
        if policy is not None:
            policy.reset(session.policy_context(self._expert(plan) if policy.needs_simulator else None))
        return session

    def _expert(self, plan: EpisodePlan) -> PolicyType | None:
        """The scripted expert registered for the plan's task type (MetaWorld's per task), or None: the policy
        says whether it needs one."""
        with contextlib.suppress(LookupError):
            return self.plugins.expert(plan.task_type)
        return None

    def close(self) -> None:
        suite, self._suite = self._suite, None
        if suite is not None:
            suite.close()
