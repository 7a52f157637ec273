"""The feature map: a robot's move groups and an episode's cameras as LeRobot features.

Every adapter between our observations/actions and flat arrays goes through it: the recorder
(:mod:`molmo_lerobot.export.frames`), LeRobot policies (:mod:`molmo_lerobot.policies.lerobot_policy`),
the replay policy, the Gymnasium env and ``lerobot-eval``'s env (:mod:`molmo_lerobot.gym_env`,
``lerobot_env_molmo``) and molmo-pi0's DROID requests. It fixes, once:

* ``observation.images.<camera>``: ``video``, uint8 ``(H, W, 3)``, one per camera in the episode's
  camera order; a ``/`` in a camera name becomes ``_`` (so ``a/b`` and ``a_b`` collide, which
  benchmark validation refuses);
* ``observation.state``: ``float32``, each move group's ``qpos`` flattened, concatenated in the
  robot's move-group order (a group's state may hold more values than its action: two fingers);
* ``action``: ``float32``, each move group's command in the same order, sized by its move-group dimension;
* ``observation.environment_state`` (opt-in, privileged): ``float32``, the task's environment state
  (:meth:`molmo_lerobot.tasks.base.Task.environment_state`, e.g. pick: the object's pose in the robot
  base frame, its half extents and the TCP-to-object vector), named by the task; an observation
  carries it as ``environment_state``. Only a run that asks for it has it
  (``record_environment_state=true``, or a policy that reads it); a policy that reads it sees the
  simulator's ground truth, so it is not a vision policy;
* ``names``: a group's declared joint names where they fit its size, else ``<group>`` (one value)
  or ``<group>_<i>``.

A mobile robot's ``base`` is one more move group: it takes its place in every feature with no
code of its own.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from molmo_lerobot.errors import MolmoError

IMAGE_PREFIX = "observation.images."
STATE = "observation.state"
ENV_STATE = "observation.environment_state"
#: the observation key of the environment state (LeRobot's env convention names it so too)
ENV_STATE_KEY = "environment_state"
ACTION = "action"


class FeatureError(MolmoError, ValueError):
    """A value does not fit its feature; the message names the feature."""


def safe_name(name: str) -> str:
    """LeRobot feature names and keys must not contain ``/``."""
    return str(name).replace("/", "_")


def image_feature(camera: str) -> str:
    """The feature of a camera's frames (different names can map to one: ``a/b``, ``a_b``)."""
    return IMAGE_PREFIX + safe_name(camera)


def camera_of(feature: str, cameras: Iterable[str]) -> str | None:
    """The camera among ``cameras`` recorded as image ``feature`` (a camera named as its key first)."""
    names = list(cameras)
    short = feature.removeprefix(IMAGE_PREFIX)
    if short in names:
        return short
    return next((c for c in names if image_feature(c) == feature), None)


def is_wrist(camera: str) -> bool:
    """Whether a camera is a wrist camera, judged by its name."""
    return "wrist" in camera.lower()


def value_names(group: str, declared: Sequence[str] | None, size: int) -> list[str]:
    """The ``names`` of a move group's ``size`` values: its declared joints if they fit."""
    if declared is not None and len(declared) == size:
        return [safe_name(n) for n in declared]
    if size == 1:
        return [safe_name(group)]
    return [f"{safe_name(group)}_{i}" for i in range(size)]


def concat(parts: Mapping[str, Any], groups: Sequence[str], field: str,
           sizes: Sequence[int] | None = None) -> np.ndarray:
    """float32: each group's values of ``parts`` flattened, in ``groups`` order (``sizes``: checked)."""
    out = []
    for i, group in enumerate(groups):
        if group not in parts:
            raise FeatureError(f"{field}: move group {group!r} missing")
        a = np.asarray(parts[group], dtype=np.float32).reshape(-1)
        if sizes is not None and a.size != sizes[i]:
            raise FeatureError(f"{field}: move group {group!r} has {a.size} values, expected {sizes[i]}")
        out.append(a)
    return np.concatenate(out)


def split(vector: Any, move_groups: Mapping[str, int], field: str = ACTION) -> dict[str, Any]:
    """A vector (or a chunk: groups along the last axis) cut into ``move_groups`` in their order (views)."""
    n = sum(move_groups.values())
    if np.shape(vector)[-1] != n:
        raise FeatureError(f"{field}: {np.shape(vector)[-1]} values, move groups {dict(move_groups)} need {n}")
    out, start = {}, 0
    for group, dim in move_groups.items():
        out[group] = vector[..., start:start + dim]
        start += dim
    return out


def env_state_vector(value: Any, size: int) -> np.ndarray:
    """An observation's ``environment_state`` as the float32 feature of ``size`` values."""
    a = np.asarray(value, dtype=np.float32).reshape(-1)
    if a.size != size:
        raise FeatureError(f"{ENV_STATE}: {a.size} values, expected {size}")
    return a


@dataclass(frozen=True)
class FeatureMap:
    """Cameras and move groups ⇄ LeRobot features; see the module docstring."""

    cameras: tuple[tuple[str, int, int], ...]  # (camera, height, width), in the episode's order
    groups: tuple[str, ...]  # move groups, in the order their values are concatenated
    state_sizes: tuple[int, ...]
    action_sizes: tuple[int, ...]
    state_names: tuple[str, ...]
    action_names: tuple[str, ...]
    env_state_names: tuple[str, ...] = ()  # empty: no ``observation.environment_state``

    @classmethod
    def build(cls, move_groups: Mapping[str, int], joint_names: Mapping[str, Sequence[str]] | None = None,
              cameras: Iterable[tuple[str, int, int]] = (), state_sizes: Mapping[str, int] | None = None,
              env_state_names: Sequence[str] = ()) -> FeatureMap:
        """The map of ``move_groups`` (group -> action dimension, in order); a group's state has
        ``state_sizes[group]`` values (default: its action dimension); ``env_state_names``: the
        task's environment state, if the map has one."""
        joints = joint_names or {}
        sizes = state_sizes if state_sizes is not None else move_groups
        state_names: list[str] = []
        action_names: list[str] = []
        for group, dim in move_groups.items():
            state_names += value_names(group, joints.get(group), int(sizes[group]))
            action_names += value_names(group, joints.get(group), int(dim))
        return cls(
            cameras=tuple((str(c), int(h), int(w)) for c, h, w in cameras), groups=tuple(move_groups),
            state_sizes=tuple(int(sizes[g]) for g in move_groups),
            action_sizes=tuple(int(d) for d in move_groups.values()),
            state_names=tuple(state_names), action_names=tuple(action_names),
            env_state_names=tuple(safe_name(n) for n in env_state_names),
        )

    @classmethod
    def from_observation(cls, move_groups: Mapping[str, int], joint_names: Mapping[str, Sequence[str]],
                         camera_names: Iterable[str], obs: Mapping[str, Any],
                         env_state_names: Sequence[str] = ()) -> FeatureMap:
        """The map whose image and state sizes are those of an observation; with the environment
        state named ``env_state_names`` when the observation carries one."""
        images = obs.get("images") or {}
        cameras = []
        for cam in camera_names:
            if cam not in images:
                raise FeatureError(f"observation has no image for camera {cam!r} (has {sorted(images)})")
            h, w = np.asarray(images[cam]).shape[:2]
            cameras.append((cam, h, w))
        qpos = obs.get("qpos") or {}
        for group in move_groups:
            if group not in qpos:
                raise FeatureError(f"observation qpos has no move group {group!r} (has {sorted(qpos)})")
        names: Sequence[str] = ()
        if obs.get(ENV_STATE_KEY) is not None:
            names = env_state_names
            size = np.asarray(obs[ENV_STATE_KEY]).size
            if size != len(names):
                raise FeatureError(f"{ENV_STATE}: {size} values, named {list(names)}")
        return cls.build(move_groups, joint_names, cameras, {g: np.asarray(qpos[g]).size for g in move_groups},
                         names)

    @property
    def move_groups(self) -> dict[str, int]:
        return dict(zip(self.groups, self.action_sizes, strict=True))

    @property
    def camera_shapes(self) -> dict[str, tuple[int, int, int]]:
        return {cam: (h, w, 3) for cam, h, w in self.cameras}

    def action_layout(self) -> str:
        """The action's move groups in order, e.g. ``arm (7) + gripper (1)``."""
        return " + ".join(f"{g} ({d})" for g, d in self.move_groups.items())

    @property
    def state_dim(self) -> int:
        return sum(self.state_sizes)

    @property
    def action_dim(self) -> int:
        return sum(self.action_sizes)

    def features(self) -> dict[str, dict[str, Any]]:
        """The image, ``observation.state``, ``observation.environment_state`` (if the map has one) and
        ``action`` entries of ``LeRobotDataset.create``'s ``features``."""
        feats: dict[str, dict[str, Any]] = {}
        for cam, h, w in self.cameras:
            feats[image_feature(cam)] = {"dtype": "video", "shape": (h, w, 3), "names": ["height", "width", "channels"]}
        feats[STATE] = {"dtype": "float32", "shape": (self.state_dim,), "names": list(self.state_names)}
        if self.env_state_names:
            feats[ENV_STATE] = {"dtype": "float32", "shape": (len(self.env_state_names),),
                                "names": list(self.env_state_names)}
        feats[ACTION] = {"dtype": "float32", "shape": (self.action_dim,), "names": list(self.action_names)}
        return feats

    def images(self, images: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """Image feature -> the camera's uint8 (H, W, 3) image, checked against the map."""
        out = {}
        for cam, h, w in self.cameras:
            feature = image_feature(cam)
            img = images.get(cam)
            if img is None:
                raise FeatureError(f"{feature}: missing in this step")
            img = np.asarray(img)
            if img.shape != (h, w, 3) or img.dtype != np.uint8:
                raise FeatureError(f"{feature}: got {img.dtype} {img.shape}, expected uint8 {(h, w, 3)}")
            out[feature] = img
        return out

    def state_vector(self, qpos: Mapping[str, Any]) -> np.ndarray:
        """``observation.state`` of an observation's ``qpos``."""
        return concat(qpos, self.groups, STATE, self.state_sizes)

    def env_state_vector(self, obs: Mapping[str, Any]) -> np.ndarray:
        """``observation.environment_state`` of an observation, checked against the map."""
        if not self.env_state_names:
            raise FeatureError(f"{ENV_STATE}: this feature map has none")
        value = obs.get(ENV_STATE_KEY)
        if value is None:
            raise FeatureError(f"{ENV_STATE}: missing in this step")
        return env_state_vector(value, len(self.env_state_names))

    def action_vector(self, action: Mapping[str, Any]) -> np.ndarray:
        """``action`` of a per-move-group action."""
        return concat(action, self.groups, ACTION, self.action_sizes)

    def split_action(self, vector: Any) -> dict[str, Any]:
        """A flat action (or a chunk of them) -> per move group."""
        return split(vector, self.move_groups)
