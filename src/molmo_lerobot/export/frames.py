"""How one rollout step becomes one LeRobot frame: the dataset schema and the frame dict.

The schema is fixed by the first step of an episode: the feature map of its robot's move groups,
its cameras at their resolution and, when the observations carry it, the task's environment
state (:mod:`molmo_lerobot.features`), and whether the task defines a reward; so every frame of
a dataset shard has exactly the same keys, shapes and names.

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

from molmo_lerobot.features import ACTION, ENV_STATE, STATE, FeatureError, FeatureMap
from molmo_lerobot.recording import EpisodeInfo

EVAL_EPISODE_INDEX = "eval.episode_index"
EVAL_SEED = "eval.seed"


@dataclass(frozen=True)
class FrameLayout:
    """The dataset schema of one recording: its feature map, reward presence and robot."""

    feature_map: FeatureMap
    has_reward: bool
    robot_type: str | None = None

    @classmethod
    def from_step(cls, info: EpisodeInfo, obs: dict[str, Any], reward: float | None) -> FrameLayout:
        """Derive the schema from an episode's info and its first observation."""
        fmap = FeatureMap.from_observation(info.move_groups, info.joint_names, info.camera_names, obs,
                                           info.environment_state_names)
        return cls(feature_map=fmap, has_reward=reward is not None, robot_type=info.extra.get("robot"))

    def features(self) -> dict[str, dict[str, Any]]:
        """The ``features`` argument of ``LeRobotDataset.create``."""
        feats = self.feature_map.features()
        if self.has_reward:
            feats["next.reward"] = {"dtype": "float32", "shape": (1,), "names": None}
        feats["next.success"] = {"dtype": "bool", "shape": (1,), "names": None}
        feats["next.done"] = {"dtype": "bool", "shape": (1,), "names": None}
        feats[EVAL_EPISODE_INDEX] = {"dtype": "int64", "shape": (1,), "names": None}
        feats[EVAL_SEED] = {"dtype": "int64", "shape": (1,), "names": None}
        return feats

    def frame(self, obs: dict[str, Any], action: dict[str, Any], reward: float | None,
              success: bool, done: bool, task: str, info: EpisodeInfo) -> dict[str, Any]:
        """One ``add_frame`` dict; raises :class:`~molmo_lerobot.features.FeatureError` naming the misfit."""
        fmap = self.feature_map
        frame: dict[str, Any] = fmap.images(obs.get("images") or {})
        frame[STATE] = fmap.state_vector(obs.get("qpos") or {})
        if fmap.env_state_names:
            frame[ENV_STATE] = fmap.env_state_vector(obs)
        frame[ACTION] = fmap.action_vector(action)
        if self.has_reward:
            if reward is None:
                raise FeatureError("next.reward: the task returned None after defining a reward")
            frame["next.reward"] = np.array([reward], dtype=np.float32)
        frame["next.success"] = np.array([bool(success)])
        frame["next.done"] = np.array([bool(done)])
        frame[EVAL_EPISODE_INDEX] = np.array([info.episode_index], dtype=np.int64)
        frame[EVAL_SEED] = np.array([info.seed], dtype=np.int64)
        frame["task"] = task
        return frame
