"""Env-suite benchmarks: ``molmo-eval benchmark=libero_object`` and its kin.

A suite benchmark is named by a config with ``suite: libero`` (``conf/benchmark/libero_*.yaml``); its
episodes are the suite's own episode specs (:class:`~molmo_lerobot.suites.libero.LiberoEpisode`, planned in
``lerobot-eval``'s order and seeding from the suite's task catalogue), not MolmoSpaces episode files. Each
becomes an :class:`~molmo_lerobot.runner.plan.EpisodePlan` (spec: the episode's fields plus ``env_suite``;
digest: the episode's), so workers, executors, resume, ``results.json`` (one ``per_task`` row per LIBERO task),
``episodes.jsonl``, compare and report are the same code as for our benchmarks. A worker plays a suite plan
in a :class:`SuiteSession` on its own suite process, started at its first such episode and kept across episodes
(:class:`SuiteSessions`).

Options (``benchmark.<key>=``): ``episodes_per_task`` (default 1; ``lerobot-eval``'s ``--eval.n_episodes``),
``image_size`` (camera images, default LeRobot's 360), ``hard_reset`` (default true, LeRobot's default).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.hashing import content_sha256
from molmo_lerobot.results import EpisodeOutcome
from molmo_lerobot.suites.libero import (
    ACTION_DIM,
    CONTROL_HZ,
    IMAGE_SIZE,
    MOVE_GROUP,
    LiberoEpisode,
    LiberoSuite,
    plan_episodes,
    policy_observation,
)
from molmo_lerobot.suites.libero_dataset import LiberoDatasetLayout

if TYPE_CHECKING:
    from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy
    from molmo_lerobot.recording import EpisodeInfo
    from molmo_lerobot.results import EpisodeResult
    from molmo_lerobot.run_config import RunConfig
    from molmo_lerobot.runner.plan import EpisodePlan

#: the key of a plan's spec that names its env suite (absent: one of our own episodes)
SUITE_KEY = "env_suite"
#: the suites molmo-eval runs (``benchmark.suite``)
SUITES = ("libero",)
_CAMERAS = ("image", "image2")


class SuiteBenchmarkError(MolmoError, ValueError):
    """A suite benchmark's options are wrong; the message names the key."""


def suite_options(config: RunConfig) -> dict[str, Any]:
    """The suite benchmark's options from ``benchmark.*``, checked (one clear error naming the key)."""
    bench = config.benchmark.model_dump()
    if bench.get("suite") not in SUITES:
        raise SuiteBenchmarkError(f"benchmark.suite: unknown env suite {bench.get('suite')!r} "
                                  f"(known: {', '.join(SUITES)})")
    out = {"episodes_per_task": bench.get("episodes_per_task", 1), "image_size": bench.get("image_size", IMAGE_SIZE),
           "hard_reset": bench.get("hard_reset", True)}
    for key in ("episodes_per_task", "image_size"):
        if not isinstance(out[key], int) or isinstance(out[key], bool) or out[key] < 1:
            raise SuiteBenchmarkError(f"benchmark.{key}: expected an integer >= 1, got {out[key]!r}")
    if not isinstance(out["hard_reset"], bool):
        raise SuiteBenchmarkError(f"benchmark.hard_reset: expected true or false, got {out['hard_reset']!r}")
    unknown = sorted(set(bench) - {"name", "path", "suite", *out})
    if unknown:
        raise SuiteBenchmarkError(f"benchmark.{unknown[0]}: not an option of env-suite benchmarks "
                                  f"(options: {', '.join(out)})")
    return out


def is_suite(config: RunConfig) -> bool:
    """Whether ``config.benchmark`` names an env-suite benchmark."""
    return bool(config.benchmark.model_dump().get("suite"))


def recording_layout(config: RunConfig) -> LiberoDatasetLayout | None:
    """The dataset schema ``record=true`` writes a LIBERO run in (LeRobot's LIBERO datasets' layout, at the
    run's ``image_size``); None for other runs, whose schema follows each recording's first step."""
    if config.benchmark.model_dump().get("suite") != "libero":
        return None
    return LiberoDatasetLayout(suite_options(config)["image_size"])


@dataclass(frozen=True)
class Origin:
    file: str


@dataclass
class SuiteBenchmark:
    """A suite's episodes for one run: what the run directory, selection and summary read of a benchmark."""

    name: str
    episodes: list[LiberoEpisode]
    path: Path

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
    """The suite's episodes for ``config``: its task catalogue (read from the suite's process), then
    ``episodes_per_task`` episodes per task with the run's seed, ``horizon`` overriding LeRobot's step limit."""
    options = suite_options(config)
    name = str(config.benchmark.name)
    suite = LiberoSuite()
    try:
        tasks = suite.tasks(name)
    finally:
        suite.close()
    episodes = plan_episodes(name, tasks, options["episodes_per_task"], seed=config.seed, horizon=config.horizon)
    return SuiteBenchmark(name, episodes, Path(f"{SUITES[0]}:{name}"))


def task_label(episode: LiberoEpisode) -> str:
    """The episode's task as ``results.json``'s ``per_task`` key: ``libero_object/task_03``."""
    return f"{episode.suite}/task_{episode.task_id:02d}"


def plan_episode(plan: EpisodePlan) -> LiberoEpisode:
    """The suite episode a plan carries."""
    return LiberoEpisode(**{f.name: plan.spec[f.name] for f in fields(LiberoEpisode)})


class _SuiteEnv:
    """What the rollout loop and the worker read of a session's env."""

    def __init__(self) -> None:
        self.move_groups = {MOVE_GROUP: ACTION_DIM}
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

    def __init__(self, plan: EpisodePlan, suite: LiberoSuite, image_size: int, end_on_success: bool) -> None:
        self.plan, self.suite, self.image_size = plan, suite, image_size
        self.episode = plan_episode(plan)
        self.env, self.task = _SuiteEnv(), _SuiteTask()
        self.end_on_success = end_on_success
        super().__init__()
        self.terminated = False
        self._obs = suite.reset(self.episode)

    @property
    def horizon(self) -> int:
        return int(self.plan.horizon or 0)

    def policy_context(self) -> EpisodeContext:
        from molmo_lerobot.policies.base import EpisodeContext

        return EpisodeContext(spec=None, episode_index=self.plan.episode_index, seed=self.plan.seed,
                              prompt=self.plan.prompt, move_groups=dict(self.env.move_groups),
                              policy_dt_s=1.0 / CONTROL_HZ, extra={"delta_groups": [MOVE_GROUP]})

    def recorder_info(self, *, expert: bool, extra: dict[str, Any]) -> EpisodeInfo:
        from molmo_lerobot.recording import EpisodeInfo

        plan = self.plan
        return EpisodeInfo(episode_index=plan.episode_index, house_index=None, seed=plan.seed, prompt=plan.prompt,
                           task_type=plan.task_type, fps=float(CONTROL_HZ), horizon=self.horizon,
                           camera_names=list(_CAMERAS), img_resolution=(self.image_size, self.image_size),
                           joint_names={}, move_groups=dict(self.env.move_groups), expert=expert,
                           extra={"suite": self.episode.suite, "task_id": self.episode.task_id,
                                  "init_state_index": self.episode.init_state_index, **extra})

    def observe(self, images: bool = True) -> Observation:
        return policy_observation({**self._obs, "task": self.plan.prompt}, self.steps)

    def complete(self, action: Action) -> Action:
        return action

    def step(self, action: Action, *, observed: bool = True) -> bool:
        reply = self.suite.step(np.asarray(action[MOVE_GROUP], dtype=np.float64))
        self._obs, self.task.last_reward = reply["observation"], float(reply["reward"])
        self.terminated = bool(reply["terminated"])
        return self.count_step(bool(reply["success"]), observed)

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
                   "success_any_step": self.success_any_step, "suite": self.episode.suite,
                   "task_id": self.episode.task_id, "init_state_index": self.episode.init_state_index,
                   "digest": self.episode.digest})

    def close(self) -> None:
        """Nothing: the suite process outlives the episode (:class:`SuiteSessions`)."""


class SuiteSessions:
    """A worker's suite process, started at its first suite episode and kept until :meth:`close`."""

    def __init__(self, config: RunConfig) -> None:
        self.config = config
        self._suite: LiberoSuite | None = None

    def open(self, plan: EpisodePlan, policy: Policy | None, end_on_success: bool) -> SuiteSession:
        options = suite_options(self.config)
        if self._suite is None:
            self._suite = LiberoSuite(image_size=options["image_size"], hard_reset=options["hard_reset"])
        session = SuiteSession(plan, self._suite, options["image_size"], end_on_success)
        if policy is not None:
            policy.reset(session.policy_context())
        return session

    def close(self) -> None:
        suite, self._suite = self._suite, None
        if suite is not None:
            suite.close()
