"""How one rollout step becomes one LeRobot frame: the feature schema and the frame dict.

The schema is fixed by the first step of an episode (robot, cameras and their resolution,
the move groups in ``EpisodeInfo.move_groups`` order, whether the task defines a reward), so
every frame of a dataset shard has exactly the same keys, shapes and names.

Every frame also carries its provenance as plain data columns, which every LeRobot edit
(``lerobot-edit-dataset`` delete / split / merge / modify_tasks / recompute_stats) keeps:
``eval.episode_index`` (the benchmark episode: the key into ``meta/eval/episodes.jsonl``
and ``episodes.jsonl``) and ``eval.seed``. LeRobot policies ignore them (only
``observation.*`` and ``action`` keys become policy features).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from molmo_lerobot.runner.recorders import EpisodeInfo

IMAGE_PREFIX = "observation.images."
EVAL_EPISODE_INDEX = "eval.episode_index"
EVAL_SEED = "eval.seed"


class FrameError(ValueError):
    """A step does not fit the dataset schema; the message names the field."""


def _safe(name: str) -> str:
    """LeRobot feature names and keys must not contain ``/``."""
    return str(name).replace("/", "_")


def image_feature(camera: str) -> str:
    """The dataset feature of a camera's frames (different names can map to one: ``a/b``, ``a_b``)."""
    return IMAGE_PREFIX + _safe(camera)


def _names(group: str, declared: list[str] | None, size: int) -> list[str]:
    if declared is not None and len(declared) == size:
        return [_safe(n) for n in declared]
    if size == 1:
        return [_safe(group)]
    return [f"{_safe(group)}_{i}" for i in range(size)]


@dataclass(frozen=True)
class FrameLayout:
    """The dataset schema of one recording: cameras, state/action layout and reward presence."""

    cameras: tuple[tuple[str, int, int], ...]  # (camera name, height, width)
    groups: tuple[str, ...]
    state_names: tuple[str, ...]
    state_sizes: tuple[int, ...]
    action_names: tuple[str, ...]
    action_sizes: tuple[int, ...]
    has_reward: bool
    robot_type: str | None = None

    @classmethod
    def from_step(cls, info: EpisodeInfo, obs: dict[str, Any], reward: float | None) -> FrameLayout:
        """Derive the schema from an episode's info and its first observation."""
        images = obs.get("images") or {}
        cameras = []
        for cam in info.camera_names:
            if cam not in images:
                raise FrameError(f"observation has no image for camera {cam!r} (has {sorted(images)})")
            h, w = np.asarray(images[cam]).shape[:2]
            cameras.append((cam, int(h), int(w)))
        qpos = obs.get("qpos") or {}
        state_names: list[str] = []
        state_sizes: list[int] = []
        action_names: list[str] = []
        for group, dim in info.move_groups.items():
            if group not in qpos:
                raise FrameError(f"observation qpos has no move group {group!r} (has {sorted(qpos)})")
            size = int(np.asarray(qpos[group]).size)
            joints = info.joint_names.get(group)
            state_names += _names(group, joints, size)
            state_sizes.append(size)
            action_names += _names(group, joints, int(dim))
        return cls(
            cameras=tuple(cameras), groups=tuple(info.move_groups), state_names=tuple(state_names),
            state_sizes=tuple(state_sizes), action_names=tuple(action_names),
            action_sizes=tuple(int(d) for d in info.move_groups.values()), has_reward=reward is not None,
            robot_type=info.extra.get("robot"),
        )

    def features(self) -> dict[str, dict[str, Any]]:
        """The ``features`` argument of ``LeRobotDataset.create``."""
        feats: dict[str, dict[str, Any]] = {}
        for cam, h, w in self.cameras:
            feats[image_feature(cam)] = {
                "dtype": "video", "shape": (h, w, 3), "names": ["height", "width", "channels"],
            }
        feats["observation.state"] = {"dtype": "float32", "shape": (len(self.state_names),),
                                      "names": list(self.state_names)}
        feats["action"] = {"dtype": "float32", "shape": (len(self.action_names),), "names": list(self.action_names)}
        if self.has_reward:
            feats["next.reward"] = {"dtype": "float32", "shape": (1,), "names": None}
        feats["next.success"] = {"dtype": "bool", "shape": (1,), "names": None}
        feats["next.done"] = {"dtype": "bool", "shape": (1,), "names": None}
        feats[EVAL_EPISODE_INDEX] = {"dtype": "int64", "shape": (1,), "names": None}
        feats[EVAL_SEED] = {"dtype": "int64", "shape": (1,), "names": None}
        return feats

    def frame(self, obs: dict[str, Any], action: dict[str, Any], reward: float | None,
              success: bool, done: bool, task: str, info: EpisodeInfo) -> dict[str, Any]:
        """One ``add_frame`` dict; raises :class:`FrameError` naming the field that does not fit."""
        frame: dict[str, Any] = {}
        images = obs.get("images") or {}
        for cam, h, w in self.cameras:
            img = images.get(cam)
            if img is None:
                raise FrameError(f"observation.images.{cam}: missing in this step")
            img = np.asarray(img)
            if img.shape != (h, w, 3) or img.dtype != np.uint8:
                raise FrameError(f"observation.images.{cam}: got {img.dtype} {img.shape}, expected uint8 {(h, w, 3)}")
            frame[image_feature(cam)] = img
        frame["observation.state"] = self._concat(obs.get("qpos") or {}, self.state_sizes, "observation.state")
        frame["action"] = self._concat(action, self.action_sizes, "action")
        if self.has_reward:
            if reward is None:
                raise FrameError("next.reward: the task returned None after defining a reward")
            frame["next.reward"] = np.array([reward], dtype=np.float32)
        frame["next.success"] = np.array([bool(success)])
        frame["next.done"] = np.array([bool(done)])
        frame[EVAL_EPISODE_INDEX] = np.array([info.episode_index], dtype=np.int64)
        frame[EVAL_SEED] = np.array([info.seed], dtype=np.int64)
        frame["task"] = task
        return frame

    def _concat(self, parts: dict[str, Any], sizes: tuple[int, ...], field: str) -> np.ndarray:
        out = []
        for group, size in zip(self.groups, sizes, strict=True):
            if group not in parts:
                raise FrameError(f"{field}: move group {group!r} missing")
            a = np.asarray(parts[group], dtype=np.float32).reshape(-1)
            if a.size != size:
                raise FrameError(f"{field}: move group {group!r} has {a.size} values, expected {size}")
            out.append(a)
        return np.concatenate(out)
