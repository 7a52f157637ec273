"""Recorders subscribe to the one rollout loop (LeRobot export, videos, metrics).

A :class:`RecorderFactory` is built in the main process from the run config, pickled to
every worker (process or Ray actor), and asked for one :class:`Recorder` per worker. After
all workers are done, ``finalize`` runs once in the main process (e.g. to merge per-worker
dataset shards).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from molmo_lerobot.policies.base import Action, Observation
    from molmo_lerobot.runner.results import EpisodeResult


@dataclass
class EpisodeInfo:
    """What a recorder learns when an episode starts."""

    episode_index: int
    house_index: int | None
    seed: int
    prompt: str
    task_type: str
    fps: float
    horizon: int
    camera_names: list[str]
    img_resolution: tuple[int, int]  # (width, height)
    joint_names: dict[str, list[str]]
    move_groups: dict[str, int]
    #: the policy is a privileged scripted expert (it reads the simulator): its rollouts are demonstrations
    expert: bool = False
    extra: dict[str, Any] = field(default_factory=dict)


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

    def close(self) -> None:
        """The worker is done: flush and finish this worker's output."""


class RecorderFactory(ABC):
    """Picklable recipe for per-worker recorders plus the run-level finishing step."""

    @abstractmethod
    def make(self, worker_id: str, output_dir: Path) -> Recorder: ...

    def finalize(self, output_dir: Path, results: list[EpisodeResult], summary: dict[str, Any]) -> None:
        """Runs once in the main process after every worker closed."""
