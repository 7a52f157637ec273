"""DROID observation/action conventions used by pi0_droid, pi0_fast_droid and pi05_droid."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from molmo_lerobot.policies.image_ops import resize_with_pad

EXTERIOR = "observation/exterior_image_1_left"
WRIST = "observation/wrist_image_left"
JOINTS = "observation/joint_position"
GRIPPER = "observation/gripper_position"
PROMPT = "prompt"
ACTIONS = "actions"


class GripperConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")

    obs_open: float = 0.0
    obs_closed: float = 1.0
    binarize: bool = True
    threshold: float = 0.5
    invert: bool = False


class CameraConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")

    exterior: str | None = None
    wrist: str | None = None


class DroidConfig(BaseModel):
    """How our observations and actions map onto DROID's."""

    model_config = ConfigDict(extra="ignore")

    cameras: CameraConfig = Field(default_factory=CameraConfig)
    image_size: int = Field(default=224, ge=8)
    action_mode: Literal["joint_velocity", "joint_position"] = "joint_velocity"
    velocity_scale: float = 1.0
    max_joint_delta: float | None = Field(default=None, gt=0)
    open_loop_horizon: int | None = Field(default=None, ge=1)
    action_dim: int = Field(default=8, ge=8)
    gripper: GripperConfig = Field(default_factory=GripperConfig)


def pick_cameras(cameras: CameraConfig, available: list[str]) -> tuple[str, str]:
    """(exterior, wrist) camera names; unset ones are guessed from the names (``*wrist*``)."""
    wrist = cameras.wrist or next((c for c in available if "wrist" in c.lower()), None)
    exterior = cameras.exterior or next((c for c in sorted(available) if c != wrist and "wrist" not in c.lower()), None)
    for role, name in (("exterior", exterior), ("wrist", wrist)):
        if name is None or name not in available:
            raise KeyError(
                f"pi0 needs a {role} camera: {'policy.cameras.' + role + '=' + repr(name) if name else 'none found'}; "
                f"the observation has {sorted(available)} (set policy.cameras.{role}=<camera>)"
            )
    return exterior, wrist  # type: ignore[return-value]


def droid_observation(obs: dict[str, Any], cfg: DroidConfig, prompt: str) -> dict[str, Any]:
    """Our observation dict -> the DROID request dict (224x224 letterboxed uint8 images)."""
    images = obs.get("images") or {}
    exterior, wrist = pick_cameras(cfg.cameras, list(images))
    qpos = obs.get("qpos") or {}
    if "arm" not in qpos or "gripper" not in qpos:
        raise KeyError(f"pi0 needs qpos 'arm' (7) and 'gripper' (1); observation has {sorted(qpos)}")
    arm = np.asarray(qpos["arm"], dtype=np.float64).reshape(-1)
    if arm.shape != (7,):
        raise ValueError(f"pi0 needs 7 arm joint positions, observation qpos['arm'] has shape {arm.shape}")
    g = float(np.asarray(qpos["gripper"], dtype=np.float64).reshape(-1)[0])
    span = cfg.gripper.obs_closed - cfg.gripper.obs_open
    g = float(np.clip((g - cfg.gripper.obs_open) / span if span else g, 0.0, 1.0))
    size = cfg.image_size
    return {
        EXTERIOR: resize_with_pad(images[exterior], size, size),
        WRIST: resize_with_pad(images[wrist], size, size),
        JOINTS: arm,
        GRIPPER: np.array([g], dtype=np.float64),
        PROMPT: obs.get("prompt") or prompt,
    }


def droid_actions(raw: Any, arm_qpos: np.ndarray, cfg: DroidConfig, dt_s: float, source: str) -> dict[str, np.ndarray]:
    """(H, 8) DROID actions -> our chunk ``{"arm": (H, 7) joint targets, "gripper": (H, 1) in [0, 1]}``."""
    actions = np.asarray(raw, dtype=np.float64)
    if actions.ndim == 1:
        actions = actions[None]
    if actions.ndim != 2 or actions.shape[0] < 1 or actions.shape[1] < cfg.action_dim:
        raise ValueError(f"{source}: 'actions' has shape {actions.shape}, expected (H, {cfg.action_dim})")
    if not np.isfinite(actions[:, : cfg.action_dim]).all():
        t = int(np.argwhere(~np.isfinite(actions[:, : cfg.action_dim]))[0][0])
        raise ValueError(f"{source}: 'actions' has a non-finite value at step {t}")
    if cfg.open_loop_horizon:
        actions = actions[: cfg.open_loop_horizon]
    joints, grip = actions[:, :7], actions[:, 7]
    if cfg.action_mode == "joint_velocity":
        deltas = joints * cfg.velocity_scale * dt_s
        if cfg.max_joint_delta is not None:
            deltas = np.clip(deltas, -cfg.max_joint_delta, cfg.max_joint_delta)
        arm = np.asarray(arm_qpos, dtype=np.float64).reshape(1, 7) + np.cumsum(deltas, axis=0)
    else:
        arm = joints
    if cfg.gripper.invert:
        grip = 1.0 - grip
    grip = (grip > cfg.gripper.threshold).astype(np.float64) if cfg.gripper.binarize else np.clip(grip, 0.0, 1.0)
    return {"arm": arm, "gripper": grip[:, None]}
