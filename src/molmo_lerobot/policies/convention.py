"""Observation/action conventions: the keys, units and frames a policy speaks (``policy.convention``).

``native`` is ours (:mod:`molmo_lerobot.policies.base`): images under ``images``, the gripper as
one value 0 open … 1 closed, ``tcp_pose`` in the world frame, gripper actions in [0, 1].

``molmospaces`` is what a MolmoSpaces policy gets from its sensors and returns (``molmo_spaces``
``env/sensors.py``, ``policy/learned_policy``):

* one flat entry per camera name (``<camera>: uint8 (H, W, 3)``; depth as ``<camera>_depth``);
* ``qpos`` / ``qvel``: per move group, the joints in their own units as float32 lists
  (the Robotiq 2F-85 gripper: its two driver-joint angles in rad; the Panda hand: its two
  finger positions in m);
* ``tcp_pose``: the TCP in the robot-base frame, ``x, y, z, qw, qx, qy, qz`` (float32);
  ``robot_base_pose``: the base in the world frame;
* ``task``: the instruction (their websocket client adds it to every observation);
* actions: ``{"arm": 7 absolute joint targets, "gripper": actuator command 0 open … 255 closed}``,
  one step or a chunk (a leading time axis, or their list of per-step dicts).

The mapping is a pure function of our observation (which carries ``joint_qpos``, ``joint_qvel``
and ``robot_base_pose`` for it), so it works the same in a worker and behind ``molmo-serve``.
Policies apply it at their boundary:
``policy=remote`` on the wire, ``policy=lerobot`` for ``observation.state`` and the action
vector, ``policy=pi0`` (molmo-pi0) for the DROID request; any other policy plugin is wrapped in a
:class:`ConventionAdapter` (``molmo_lerobot.policies.factory.make_policy``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from molmo_lerobot.policies.base import Action, ConventionName, EpisodeContext, Observation, Policy

#: MolmoSpaces' gripper actuator command for fully closed (0 is open)
GRIPPER_CLOSED_CMD = 255.0


class Convention:
    """The native convention: everything passes unchanged."""

    name: ConventionName = "native"

    def observation(self, obs: Observation) -> dict[str, Any]:
        """Our observation in this convention's layout (the policy's view of it)."""
        return obs

    def images(self, view: dict[str, Any]) -> dict[str, np.ndarray]:
        """Camera name -> RGB image in a view made by :meth:`observation`."""
        return view.get("images") or {}

    def action(self, action: Any) -> Action:
        """A policy's action (or chunk) in this convention -> ours."""
        return action


class MolmoSpacesConvention(Convention):
    """MolmoSpaces' keys, units and frames; see the module docstring."""

    name: ConventionName = "molmospaces"

    def observation(self, obs: Observation) -> dict[str, Any]:
        missing = [k for k in ("joint_qpos", "joint_qvel", "tcp_pose", "robot_base_pose") if k not in obs]
        if missing:
            raise KeyError(f"convention=molmospaces needs {missing} in the observation (it has {sorted(obs)})")
        view: dict[str, Any] = dict(obs.get("images") or {})
        view.update({f"{cam}_depth": depth for cam, depth in (obs.get("depth") or {}).items()})
        for key, source in (("qpos", "joint_qpos"), ("qvel", "joint_qvel")):
            view[key] = {g: np.asarray(v, dtype=np.float32).reshape(-1).tolist() for g, v in obs[source].items()}
        view["tcp_pose"] = pose_in_frame(obs["tcp_pose"], obs["robot_base_pose"]).astype(np.float32)
        view["robot_base_pose"] = np.asarray(obs["robot_base_pose"], dtype=np.float32)
        if obs.get("prompt"):
            view["task"] = obs["prompt"]
        return view

    def images(self, view: dict[str, Any]) -> dict[str, np.ndarray]:
        return {k: v for k, v in view.items() if isinstance(v, np.ndarray) and v.ndim == 3}

    def action(self, action: Any) -> Action:
        if isinstance(action, (list, tuple)):  # their chunk: one dict per step
            if not action or not all(isinstance(a, dict) for a in action):
                raise ValueError("convention=molmospaces: an action chunk must be a non-empty list of dicts")
            action = {k: np.stack([np.asarray(a[k]) for a in action]) for k in action[0]}
        if not isinstance(action, dict):
            raise ValueError(f"convention=molmospaces: expected an action dict, got {type(action).__name__}")
        out = dict(action)
        if "gripper" in out:
            out["gripper"] = np.asarray(out["gripper"], dtype=np.float64) / GRIPPER_CLOSED_CMD
        return out


class ConventionAdapter(Policy):
    """Any policy plugin written against another convention: it acts on that convention's view of
    each observation, and its actions are mapped back to ours."""

    def __init__(self, inner: Policy, convention: Convention) -> None:
        self.inner, self.convention = inner, convention
        self.needs_images, self.needs_simulator = inner.needs_images, inner.needs_simulator
        self.needs_environment_state = inner.needs_environment_state

    def reset(self, ctx: EpisodeContext) -> None:
        self.inner.reset(ctx)

    def act(self, obs: Observation) -> Action:
        return self.convention.action(self.inner.act(self.convention.observation(obs)))

    def close(self) -> None:
        self.inner.close()

    def fork(self) -> Policy | None:
        twin = self.inner.fork()
        return None if twin is None else ConventionAdapter(twin, self.convention)


CONVENTIONS: dict[str, Convention] = {"native": Convention(), "molmospaces": MolmoSpacesConvention()}


def get_convention(name: str) -> Convention:
    """The convention called ``name`` (``native`` | ``molmospaces``)."""
    try:
        return CONVENTIONS[name]
    except KeyError:
        raise ValueError(f"policy.convention={name!r}: expected one of {sorted(CONVENTIONS)}") from None


def pose_in_frame(pose: Any, frame: Any) -> np.ndarray:
    """``pose`` (world, x y z qw qx qy qz) expressed in ``frame`` (world, same layout), as MolmoSpaces
    computes ``tcp_pose`` (its quaternion from scipy, scalar first)."""
    pose, frame = np.asarray(pose, dtype=np.float64), np.asarray(frame, dtype=np.float64)
    f_rot = Rotation.from_quat(frame[3:], scalar_first=True)
    p_rot = Rotation.from_quat(pose[3:], scalar_first=True)
    pos = f_rot.inv().apply(pose[:3] - frame[:3])
    rel = (f_rot.inv().as_matrix() @ p_rot.as_matrix())
    return np.concatenate([pos, Rotation.from_matrix(rel).as_quat(scalar_first=True)])
