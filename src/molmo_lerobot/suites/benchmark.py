"""Env-suite benchmarks: ``molmo-eval benchmark=libero_object`` and its kin, ``benchmark=pusht``.

A suite benchmark is named by a config with ``suite: libero`` or ``suite: pusht`` (``conf/benchmark/libero_*.yaml``,
``pusht.yaml``); its episodes are the suite's own episode specs (:class:`~molmo_lerobot.suites.libero.LiberoEpisode`,
:class:`~molmo_lerobot.suites.pusht.PushTEpisode`, planned in ``lerobot-eval``'s order and seeding from the suite's
task catalogue), not MolmoSpaces episode files. What differs between suites is one :class:`SuiteKind`. Each
becomes an :class:`~molmo_lerobot.runner.plan.EpisodePlan` (spec: the episode's fields plus ``env_suite``;
digest: the episode's), so workers, executors, resume, ``results.json`` (one ``per_task`` row per LIBERO task),
``episodes.jsonl``, compare and report are the same code as for our benchmarks. A worker plays a suite plan
in a :class:`SuiteSession` on its own suite (LIBERO's process, PushT's env), started at its first such episode and
kept across episodes (:class:`SuiteSessions`).

Options (``benchmark.<key>=``): ``episodes_per_task`` (default 1; ``lerobot-eval``'s ``--eval.n_episodes``),
``image_size`` (camera images, default LeRobot's: LIBERO 360, PushT 96; at most :data:`MAX_IMAGE_SIZE`),
LIBERO's ``hard_reset`` (default true, LeRobot's default).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from molmo_lerobot.errors import InfrastructureError, MolmoError, describe
from molmo_lerobot.hashing import content_sha256
from molmo_lerobot.results import EpisodeOutcome
from molmo_lerobot.suites import libero, metaworld, pusht
from molmo_lerobot.suites.dataset import SuiteDatasetLayout
from molmo_lerobot.suites.libero_dataset import ROBOT_TYPE as LIBERO_ROBOT
from molmo_lerobot.suites.libero_dataset import libero_layout
from molmo_lerobot.suites.metaworld_dataset import ROBOT_TYPE as METAWORLD_ROBOT
from molmo_lerobot.suites.metaworld_dataset import metaworld_layout
from molmo_lerobot.suites.pipe import SuiteError
from molmo_lerobot.suites.pusht_dataset import pusht_layout

if TYPE_CHECKING:
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyType
    from molmo_lerobot.recording import EpisodeInfo
    from molmo_lerobot.results import EpisodeResult
    from molmo_lerobot.run_config import RunConfig
    from molmo_lerobot.runner.plan import EpisodePlan

#: the key of a plan's spec that names its env suite (absent: one of our own episodes)
SUITE_KEY = "env_suite"
#: the largest ``benchmark.image_size``: the side of the largest frames drawn (LIBERO draws 4096², its offscreen
#: buffer grown to fit; a side beyond that can exceed the GL renderbuffer limit)
MAX_IMAGE_SIZE = 4096


@dataclass(frozen=True)
class SuiteKind:
    """What one env suite brings: its episode type and planner, its env (``open(options)``: an object with
    ``tasks``, ``reset``, ``step``, ``close`` and ``alive``), its policy interface and its options with their
    defaults."""

    episode: type[Any]
    plan: Callable[..., list[Any]]
    open: Callable[[dict[str, Any]], Any]
    task_label: Callable[[Any], str]
    observation: Callable[[Any, int], Observation]
    move_group: str
    action_dim: int
    control_hz: float
    #: our camera -> the feature LeRobot's env hands a policy its frames as (``preprocess_observation``'s name)
    cameras: dict[str, str]
    options: dict[str, Any]
    #: what the policy learns of the action (``EpisodeContext.extra``): ``delta_groups`` (LIBERO's delta-EEF
    #: command) or ``action_bounds`` (PushT's target position, within the workspace)
    action_extra: dict[str, Any]
    #: its benchmarks (``benchmark=<name>``, each a ``conf/benchmark/<name>.yaml``) and LeRobot's step limit
    #: of each (the default horizon)
    benchmarks: dict[str, int]
    #: the problems of one planned episode against the suite's task catalogue (``[]``: none)
    check_episode: Callable[[Any, list[dict[str, Any]]], list[str]]
    #: the distributions its env and assets come from (``molmo-bench list`` shows their version and licence)
    distributions: tuple[str, ...]
    #: where those distributions live: ``"main"`` (this venv) or ``"libero"`` (the LIBERO venv)
    venv: str = "main"
    #: the dataset layout ``record=true`` writes (``recording(options)``: the schema of the suite's LeRobot
    #: datasets, ``lerobot/libero``'s, ``lerobot/pusht``'s); None: ``record=true`` is refused
    recording: Callable[[dict[str, Any]], SuiteDatasetLayout] | None = None
    #: the robot its env builds (its datasets' ``robot_type``); None: none (PushT's pusher)
    robot: str | None = None
    #: a fault of the installed files its env reads in place (one line naming the file and what to reinstall),
    #: or None: checked before any worker starts, and after an episode failed (then the machine's failure)
    install_problem: Callable[[], str | None] | None = None


def _libero_label(episode: libero.LiberoEpisode) -> str:
    return f"{episode.suite}/task_{episode.task_id:02d}"


#: the suites molmo-eval runs (``benchmark.suite``)
SUITES: dict[str, SuiteKind] = {
    "libero": SuiteKind(
        episode=libero.LiberoEpisode, plan=libero.plan_episodes,
        open=lambda o: libero.LiberoSuite(image_size=o["image_size"], hard_reset=o["hard_reset"]),
        task_label=_libero_label, observation=libero.policy_observation, move_group=libero.MOVE_GROUP,
        action_dim=libero.ACTION_DIM, control_hz=libero.CONTROL_HZ,
        cameras={"image": "observation.images.image", "image2": "observation.images.image2"},
        options={"episodes_per_task": 1, "image_size": libero.IMAGE_SIZE, "hard_reset": True},
        action_extra={"delta_groups": [libero.MOVE_GROUP]}, benchmarks=dict(libero.MAX_STEPS),
        check_episode=libero.episode_problems, distributions=libero.DISTRIBUTIONS, venv="libero",
        recording=lambda o: libero_layout(o["image_size"]), robot=LIBERO_ROBOT,
        install_problem=libero.install_problem),
    "pusht": SuiteKind(
        episode=pusht.PushTEpisode, plan=pusht.plan_episodes,
        open=lambda o: pusht.PushTSuite(image_size=o["image_size"]),
        task_label=pusht.task_label, observation=pusht.policy_observation, move_group=pusht.MOVE_GROUP,
        action_dim=pusht.ACTION_DIM, control_hz=pusht.CONTROL_HZ, cameras={pusht.CAMERA: "observation.image"},
        options={"episodes_per_task": 1, "image_size": pusht.IMAGE_SIZE},
        action_extra={"action_bounds": {pusht.MOVE_GROUP: pusht.WORKSPACE}}, benchmarks={"pusht": pusht.MAX_STEPS},
        check_episode=pusht.episode_problems, distributions=pusht.DISTRIBUTIONS,
        recording=lambda o: pusht_layout(o["image_size"])),
    "metaworld": SuiteKind(
        episode=metaworld.MetaWorldEpisode, plan=metaworld.plan_episodes,
        open=lambda o: metaworld.MetaWorldSuite(image_size=o["image_size"]),
        task_label=metaworld.task_label, observation=metaworld.policy_observation, move_group=metaworld.MOVE_GROUP,
        action_dim=metaworld.ACTION_DIM, control_hz=metaworld.CONTROL_HZ,
        cameras={metaworld.CAMERA: "observation.image"},
        options={"episodes_per_task": 1, "image_size": metaworld.IMAGE_SIZE},
        action_extra={"action_bounds": {metaworld.MOVE_GROUP: metaworld.ACTION_BOUNDS}},
        benchmarks=metaworld.benchmarks(), check_episode=metaworld.episode_problems,
        distributions=metaworld.DISTRIBUTIONS, recording=lambda o: metaworld_layout(o["image_size"]),
        robot=METAWORLD_ROBOT),
}


def suite_benchmarks() -> dict[str, str]:
    """Every env-suite benchmark (``benchmark=<name>``) and its suite (a key of :data:`SUITES`)."""
    return {name: kind for kind, suite in SUITES.items() for name in suite.benchmarks}


class SuiteBenchmarkError(MolmoError, ValueError):
    """A suite benchmark's options are wrong; the message names the key."""


def suite_options(config: RunConfig) -> dict[str, Any]:
    """The suite benchmark's options from ``benchmark.*``, checked (one clear error naming the key)."""
    bench = config.benchmark.model_dump()
    kind = suite_kind(config)
    out = {key: bench.get(key, default) for key, default in kind.options.items()}
    for key in ("episodes_per_task", "image_size"):
        if not isinstance(out[key], int) or isinstance(out[key], bool) or out[key] < 1:
            raise SuiteBenchmarkError(f"benchmark.{key}: expected an integer >= 1, got {out[key]!r}")
    if out["image_size"] > MAX_IMAGE_SIZE:
        raise SuiteBenchmarkError(f"benchmark.image_size: at most {MAX_IMAGE_SIZE} pixels a side, got "
                                  f"{out['image_size']} (LeRobot's default: {kind.options['image_size']})")
    if not isinstance(out.get("hard_reset", True), bool):
        raise SuiteBenchmarkError(f"benchmark.hard_reset: expected true or false, got {out['hard_reset']!r}")
    unknown = sorted(set(bench) - {"name", "path", "suite", *out})
    if unknown:
        raise SuiteBenchmarkError(f"benchmark.{unknown[0]}: not an option of env-suite benchmarks "
                                  f"(options: {', '.join(out)})")
    return out


def suite_kind(config: RunConfig) -> SuiteKind:
    """The env suite ``benchmark.suite`` names (one clear error when it is none)."""
    name = config.benchmark.model_dump().get("suite")
    if name not in SUITES:
        raise SuiteBenchmarkError(f"benchmark.suite: unknown env suite {name!r} (known: {', '.join(SUITES)})")
    return SUITES[name]


def is_suite(config: RunConfig) -> bool:
    """Whether ``config.benchmark`` names an env-suite benchmark."""
    return bool(config.benchmark.model_dump().get("suite"))


def recording_layout(config: RunConfig) -> SuiteDatasetLayout | None:
    """The dataset schema ``record=true`` writes a suite run in (the suite's LeRobot datasets' layout, at the
    run's ``image_size``); None for other runs, whose schema follows each recording's first step."""
    if not is_suite(config):
        return None
    kind = suite_kind(config)
    return kind.recording(suite_options(config)) if kind.recording is not None else None


@dataclass(frozen=True)
class Origin:
    file: str


@dataclass
class SuiteBenchmark:
    """A suite's episodes for one run: what the run directory, selection and summary read of a benchmark."""

    name: str
    episodes: list[Any]
    path: Path
    #: the env suite (a key of :data:`SUITES`)
    suite: str

    @property
    def sha256(self) -> str:
        """SHA-256 of the episodes' digests in order: the benchmark's identity (a resume must match it)."""
        return content_sha256([e.digest for e in self.episodes], ensure_ascii=True).hex()

    @property
    def origins(self) -> list[Origin]:
        return []

    def where(self, index: int) -> str:
        return f"{self.name} episode {index}"


def load_suite_benchmark(config: RunConfig) -> SuiteBenchmark:
    """The suite's episodes for ``config``: its installed files checked (:class:`~molmo_lerobot.errors.
    InfrastructureError` naming the first broken one), its task catalogue (read from the suite's process), then
    ``episodes_per_task`` episodes per task with the run's seed, ``horizon`` overriding LeRobot's step limit."""
    problem = install_problem(suite_kind(config))
    if problem:
        raise InfrastructureError(f"cannot run benchmark={config.benchmark.name}: {problem}")
    return plan_suite_benchmark(config, suite_tasks(config))


def install_problem(kind: SuiteKind) -> str | None:
    """What is broken in the suite's installed files (:attr:`SuiteKind.install_problem`), or None."""
    return kind.install_problem() if kind.install_problem is not None else None


def suite_tasks(config: RunConfig) -> list[dict[str, Any]]:
    """The task catalogue of the run's suite benchmark, as the suite's own env lists it (LIBERO: its
    process in the LIBERO venv; PushT: gym_pusht's one task)."""
    options = suite_options(config)
    suite = suite_kind(config).open(options)
    try:
        return suite.tasks(str(config.benchmark.name))
    finally:
        suite.close()


def plan_suite_benchmark(config: RunConfig, tasks: list[dict[str, Any]]) -> SuiteBenchmark:
    """The run's episodes of the suite benchmark whose task catalogue is ``tasks``."""
    options = suite_options(config)
    kind_name, name = str(config.benchmark.model_dump()["suite"]), str(config.benchmark.name)
    episodes = SUITES[kind_name].plan(name, tasks, options["episodes_per_task"], seed=config.seed,
                                      horizon=config.horizon)
    return SuiteBenchmark(name, episodes, Path(f"{kind_name}:{name}"), kind_name)


def plan_problems(bench: SuiteBenchmark, tasks: list[dict[str, Any]]) -> list[str]:
    """What is wrong with ``bench``'s episodes against the suite's task catalogue ``tasks``, one line each
    naming the episode and field: the episode type and suite, a seed and a horizon >= 1, the suite's own checks
    (LIBERO: a task id of the catalogue, an init-state index within that task's init states, its instruction;
    PushT: its task), and no episode twice."""
    kind = SUITES[bench.suite]
    if bench.name not in kind.benchmarks:
        return [f"{bench.name}: not a benchmark of env suite {bench.suite!r} ({', '.join(kind.benchmarks)})"]
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


def task_label(episode: Any) -> str:
    """The episode's task as ``results.json``'s ``per_task`` key: ``libero_object/task_03``, ``pusht/PushT-v0``."""
    return next(k.task_label(episode) for k in SUITES.values() if isinstance(episode, k.episode))


def plan_episode(plan: EpisodePlan) -> Any:
    """The suite episode a plan carries."""
    cls = SUITES[plan.spec[SUITE_KEY]].episode
    return cls(**{f.name: plan.spec[f.name] for f in fields(cls)})


class _SuiteEnv:
    """What the rollout loop and the worker read of a session's env."""

    def __init__(self, kind: SuiteKind) -> None:
        self.move_groups = {kind.move_group: kind.action_dim}
        self.renderer_setup_s = 0.0


class _SuiteTask:
    def __init__(self) -> None:
        self.last_reward = 0.0

    def reward(self) -> float:
        return self.last_reward


class SuiteSession(EpisodeOutcome):
    """One suite episode, open: the :class:`~molmo_lerobot.runner.episode.EpisodeSession` interface the
    rollout loop plays, over the worker's suite process. ``lerobot-eval``'s rules: the episode ends at its
    first terminated step (LIBERO's goal reached) or at the horizon; it succeeds when its last step did."""

    def __init__(self, plan: EpisodePlan, suite: Any, image_size: int, end_on_success: bool) -> None:
        self.plan, self.suite, self.image_size = plan, suite, image_size
        self.kind = SUITES[plan.spec[SUITE_KEY]]
        self.episode = plan_episode(plan)
        self.env, self.task = _SuiteEnv(self.kind), _SuiteTask()
        self.end_on_success = end_on_success
        super().__init__()
        self.terminated = False
        self._obs = suite.reset(self.episode)

    @property
    def horizon(self) -> int:
        return int(self.plan.horizon or 0)

    def policy_context(self, expert: PolicyType | None = None, privileged: bool = False) -> EpisodeContext:
        """What the policy learns at reset; ``privileged`` (scripted experts): the suite's env too, as
        ``extra["suite"]``, and ``expert``, the one registered for the episode's task type."""
        from molmo_lerobot.policies.base import EpisodeContext

        extra = {**self.kind.action_extra, "camera_features": dict(self.kind.cameras)}
        if privileged:
            extra["suite"] = self.suite
        return EpisodeContext(spec=None, episode_index=self.plan.episode_index, seed=self.plan.seed,
                              prompt=self.plan.prompt, move_groups=dict(self.env.move_groups),
                              policy_dt_s=1.0 / self.kind.control_hz, expert=expert if privileged else None,
                              extra=extra)

    def recorder_info(self, *, expert: bool, extra: dict[str, Any]) -> EpisodeInfo:
        from molmo_lerobot.recording import EpisodeInfo

        return EpisodeInfo(identity=self.plan.identity, fps=float(self.kind.control_hz),
                           camera_names=list(self.kind.cameras), img_resolution=(self.image_size, self.image_size),
                           joint_names={}, move_groups=dict(self.env.move_groups), expert=expert,
                           extra={**self._suite_fields(), **extra})

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
        self._obs, self.task.last_reward = reply["observation"], float(reply["reward"])
        self.terminated = bool(reply["terminated"])
        return self.count_step(bool(reply["success"]), observed, self.task.last_reward)

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
        """Nothing: the suite process outlives the episode (:class:`SuiteSessions`)."""


class SuiteSessions:
    """A worker's suite (LIBERO's process, PushT's env), started at its first suite episode and kept until
    :meth:`close`; one whose process was lost is replaced at the next episode."""

    def __init__(self, config: RunConfig) -> None:
        self.config = config
        self._suite: Any = None
        self._plugins: Plugins | None = None

    def open(self, plan: EpisodePlan, policy: Policy | None, end_on_success: bool) -> SuiteSession:
        """``plan`` opened on the worker's suite, started now if it is not running (the first episode, or
        after the last one's process was lost: died, hung and killed)."""
        options = suite_options(self.config)
        if self._suite is not None and not self._suite.alive:
            self.close()
        kind = suite_kind(self.config)
        if self._suite is None:
            self._suite = kind.open(options)
        try:
            session = SuiteSession(plan, self._suite, options["image_size"], end_on_success)
        except SuiteError as exc:  # the episode's, unless the suite's installed files are broken now
            problem = install_problem(kind) if not isinstance(exc, InfrastructureError) else None
            if problem:
                raise InfrastructureError(f"{problem} (the episode failed to start: {describe(exc)})") from exc
            raise
        if policy is not None:
            privileged = policy.needs_simulator
            policy.reset(session.policy_context(self._expert(plan) if privileged else None, privileged))
        return session

    def _expert(self, plan: EpisodePlan) -> PolicyType | None:
        """The scripted expert registered for the plan's task type, or None (the policy says whether it needs one)."""
        from molmo_lerobot.plugins import Plugins

        if self._plugins is None:
            self._plugins = Plugins()
        with contextlib.suppress(LookupError):
            return self._plugins.expert(plan.task_type)
        return None

    def close(self) -> None:
        suite, self._suite = self._suite, None
        if suite is not None:
            suite.close()
