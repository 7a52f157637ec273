"""A fixed recording layout: the frame schema of published LeRobot datasets a benchmark kind records in.

LeRobot's ``aggregate_datasets`` merges only datasets whose features (names, dtypes, shapes), fps and robot type
are all equal, so ``record=true`` on an env-suite run writes exactly the features of that suite's datasets
(:meth:`BenchmarkKind.recording_layout <molmo_lerobot.benchmark_kinds.BenchmarkKind.recording_layout>`, e.g.
LIBERO's, PushT's and ALOHA's) and nothing more; the eval record of each episode is in ``meta/eval/episodes.jsonl``,
as for every recording.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from molmo_lerobot.features import FeatureError

if TYPE_CHECKING:
    from molmo_lerobot.recording import EpisodeInfo

#: the per-step outcome columns a layout may carry (``next.*``: after the frame's action), LeRobot's dtypes
OUTCOMES = {"next.reward": "float32", "next.success": "bool", "next.done": "bool"}


@dataclass(frozen=True)
class Vector:
    """One vector feature: its dataset key, size, ``names`` as the published ``info.json`` has them, and what
    it holds (the dataset card's words)."""

    key: str
    size: int
    names: Any
    about: str


@dataclass(frozen=True)
class DatasetLayout:
    """The frame schema of a suite's recording at ``image_size`` (the ``FrameLayout`` interface the recorder
    writes with: ``features``, ``frame``, ``robot_type``, ``fps``; ``describe`` for the dataset card)."""

    #: the frames' side, or (height, width) where they are not square (ALOHA's 480 × 640)
    image_size: int | tuple[int, int]
    #: our policy observation's camera -> the dataset's video feature, with what it shows
    cameras: tuple[tuple[str, str, str], ...]
    #: the move group whose ``qpos`` is the state and whose command is the action
    move_group: str
    state: Vector
    action: Vector
    robot_type: str
    #: the datasets' declared frame rate
    fps: int
    #: the real rate of the frames (one per control step; ``meta/eval/info.json`` ``fps_exact``)
    step_hz: float
    #: the image features' ``names``
    image_names: tuple[str, ...] = ("height", "width", "channel")
    #: the keys of :data:`OUTCOMES` the datasets carry per frame
    outcomes: tuple[str, ...] = ()
    #: what made the frames (the dataset card's words)
    simulator: str = ""

    def features(self) -> dict[str, dict[str, Any]]:
        """``LeRobotDataset.create``'s ``features``."""
        image = {"dtype": "video", "shape": self.image_shape, "names": list(self.image_names)}
        out: dict[str, dict[str, Any]] = {feature: dict(image) for _, feature, _ in self.cameras}
        for vector in (self.state, self.action):
            out[vector.key] = {"dtype": "float32", "shape": (vector.size,), "names": vector.names}
        if self.outcomes:
            out.update({key: {"dtype": OUTCOMES[key], "shape": (1,), "names": None} for key in self.outcomes})
        return out

    def frame(self, obs: dict[str, Any], action: dict[str, Any], reward: float | None, success: bool,
              done: bool, task: str, info: EpisodeInfo | None) -> dict[str, Any]:
        """One ``add_frame`` dict of a suite session's observation and the action taken on it (with the outcome
        after it where the layout has :data:`OUTCOMES`); raises ``FeatureError`` naming the misfit."""
        shape = self.image_shape
        frame: dict[str, Any] = {}
        for camera, feature, _ in self.cameras:
            image = np.asarray((obs.get("images") or {}).get(camera))
            if image.shape != shape or image.dtype != np.uint8:
                raise FeatureError(f"{feature}: got {image.dtype} {image.shape}, expected uint8 {shape}")
            frame[feature] = image
        frame[self.state.key] = self._vector((obs.get("qpos") or {}).get(self.move_group), self.state)
        frame[self.action.key] = self._vector(action.get(self.move_group), self.action)
        outcome = {"next.reward": 0.0 if reward is None else reward, "next.success": success, "next.done": done}
        for key in self.outcomes:
            frame[key] = np.array([outcome[key]], dtype=OUTCOMES[key])
        frame["task"] = task
        return frame

    def describe(self) -> dict[str, str]:
        """What each feature holds, by key (the dataset card's sentences)."""
        out = {feature: about for _, feature, about in self.cameras}
        out.update({self.state.key: self.state.about, self.action.key: self.action.about})
        about = {"next.reward": "the env's reward after the frame's action",
                 "next.success": "whether the env's success rule held after it",
                 "next.done": "whether the episode ended there"}
        out.update({key: about[key] for key in self.outcomes})
        return out

    @property
    def image_shape(self) -> tuple[int, int, int]:
        """A frame's (height, width, channels)."""
        size = self.image_size
        height, width = (size, size) if isinstance(size, int) else size
        return height, width, 3

    def _vector(self, value: Any, vector: Vector) -> np.ndarray:
        if value is None:
            raise FeatureError(f"{vector.key}: move group {self.move_group!r} missing")
        out = np.asarray(value, dtype=np.float32).reshape(-1)
        if out.size != vector.size:
            raise FeatureError(f"{vector.key}: {out.size} values, expected {vector.size}")
        return out
