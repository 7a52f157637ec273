"""Recorders subscribe to the one rollout loop (LeRobot export, videos, metrics).

A :class:`RecorderFactory` is built in the main process from the run config, pickled to
every worker (process or Ray actor), and asked for one :class:`Recorder` per worker. After
all workers are done, ``finalize`` runs once in the main process (e.g. to merge per-worker
dataset shards).

A worker drives its recorders through one :class:`RecorderGroup`: a recorder that raises (a
full disk, a broken plugin) fails its own output, never the episode.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot.errors import describe

if TYPE_CHECKING:
    from molmo_lerobot.assets.catalog import AssetCatalog
    from molmo_lerobot.policies.base import Action, Observation
    from molmo_lerobot.results import EpisodeIdentity, EpisodeResult, RunSummary, SummaryPiece

log = logging.getLogger(__name__)


@dataclass
class EpisodeInfo:
    """What a recorder learns when an episode starts: the episode's identity (its plan's) and how it
    is recorded."""

    identity: EpisodeIdentity
    fps: float
    camera_names: list[str]
    img_resolution: tuple[int, int]  # (width, height)
    joint_names: dict[str, list[str]]
    move_groups: dict[str, int]
    #: the policy is a privileged scripted expert (it reads the simulator): its rollouts are demonstrations
    expert: bool = False
    extra: dict[str, Any] = field(default_factory=dict)
    #: the task's environment state names when observations carry one (``observation.environment_state``)
    environment_state_names: tuple[str, ...] = ()
    #: the run's asset catalog (annotations of the scene's objects), where the worker has one
    catalog: AssetCatalog | None = None

    @property
    def episode_index(self) -> int:
        return self.identity.episode_index

    @property
    def house_index(self) -> int | None:
        return self.identity.house_index

    @property
    def seed(self) -> int:
        return self.identity.seed

    @property
    def prompt(self) -> str:
        return self.identity.prompt

    @property
    def task_type(self) -> str:
        return self.identity.task_type

    @property
    def horizon(self) -> int:
        """Policy steps (an episode that runs always has them)."""
        return int(self.identity.horizon or 0)


class Recorder(ABC):
    """Receives every step of every episode a worker runs."""

    #: Whether ``record_step`` needs rendered camera images in ``obs``.
    wants_images: bool = True

    def wants_images_at(self, step: int, horizon: int) -> bool:
        """Whether ``record_step`` at ``step`` (0 … horizon - 1) needs images; default ``wants_images``.

        A recorder that needs a few frames (thumbnails) renders only those, not the whole episode.
        """
        return self.wants_images

    @abstractmethod
    def start_episode(self, info: EpisodeInfo) -> None: ...

    @abstractmethod
    def record_step(self, obs: Observation, action: Action, reward: float | None,
                    success: bool, done: bool) -> None:
        """``obs`` is the observation the action was chosen on; the flags hold after it."""

    @abstractmethod
    def end_episode(self, result: EpisodeResult) -> None:
        """Keep the episode, or discard it if ``result.error`` is set."""

    def close(self) -> None:  # noqa: B027 - optional hook: does nothing unless overridden
        """The worker is done: flush and finish this worker's output."""


class RecorderFactory(ABC):
    """Picklable recipe for per-worker recorders plus the run-level finishing step."""

    @abstractmethod
    def make(self, worker_id: str, output_dir: Path) -> Recorder: ...

    def finalize(self, output_dir: Path, results: list[EpisodeResult],
                 summary: RunSummary) -> SummaryPiece | None:
        """Runs once in the main process after every worker closed (and the run was scored); returns
        what it adds to ``results.json``, if anything."""
        return None

    def missing(self, output_dir: Path, results: list[EpisodeResult]) -> set[int]:
        """On ``resume=true``, before any worker starts: the episodes among ``results`` whose output
        this recorder lacks and cannot make without running them (a killed worker's dataset shard);
        the resume runs them again. None by default."""
        return set()


class RecorderGroup:
    """A worker's recorders, called as one. A recorder that raises is an output failure: it gets
    no further calls in that episode, is told at its end that the episode is not its to keep (a
    copy of the result with ``error`` set), and the failure goes into ``result.output_errors``;
    the episode and the other recorders go on."""

    def __init__(self, recorders: list[Recorder]) -> None:
        self.recorders = list(recorders)
        self._failed: dict[int, str] = {}  # position in ``recorders`` -> its failure this episode

    def wants_images_at(self, step: int, horizon: int) -> bool:
        return any(r.wants_images_at(step, horizon) for i, r in enumerate(self.recorders) if i not in self._failed)

    def start_episode(self, info: EpisodeInfo) -> None:
        self._failed = {}
        self._each("start_episode", info)

    def record_step(self, obs: Observation, action: Action, reward: float | None, success: bool, done: bool) -> None:
        self._each("record_step", obs, action, reward, success, done)

    def end_episode(self, result: EpisodeResult) -> None:
        """Hand ``result`` to every recorder; the failures of this episode go into ``result.output_errors``."""
        failed, self._failed = self._failed, {}
        for i, rec in enumerate(self.recorders):
            mine = result if i not in failed else replace(result, error=f"output failed: {failed[i]}",
                                                          extra=dict(result.extra))
            self._call(i, rec.end_episode, mine, failed=failed)
        for i in sorted(failed):
            result.output_errors.append(failed[i])

    def close(self) -> None:
        """Close every recorder, even after one failed to (each failure is logged)."""
        for rec in self.recorders:
            try:
                rec.close()
            except Exception as exc:
                log.error("%s could not finish its output: %s", type(rec).__name__, describe(exc))

    def _each(self, method: str, *args: object) -> None:
        for i, rec in enumerate(self.recorders):
            if i not in self._failed:
                self._call(i, getattr(rec, method), *args, failed=self._failed)

    def _call(self, i: int, fn: Callable[..., None], *args: object, failed: dict[int, str]) -> None:
        try:
            fn(*args)
        except Exception as exc:
            failed.setdefault(i, f"{type(self.recorders[i]).__name__}: {describe(exc)}")
            log.warning("output of %s failed (the episode's outcome stands): %s", type(self.recorders[i]).__name__,
                        describe(exc))
