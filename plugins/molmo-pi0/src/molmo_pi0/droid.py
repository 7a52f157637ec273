"""DROID requests and responses: our observation -> openpi's DROID keys, its (H, 8) actions -> ours.

Two presets fit two families of checkpoints (conf/policy/pi0_*.yaml):

* ``molmospaces`` (``policy=pi0``, ``policy=pi0_molmospaces``): MolmoSpaces' ``PiPolicyEvalConfig``
  / ``PI_Policy``, for checkpoints that output absolute joint positions (openpi's
  ``pi0_fast_droid_jointpos``, ``pi05_droid_jointpos``, MolmoSpaces' fine-tunes). The request is
  built from the MolmoSpaces observation (:mod:`molmo_lerobot.policies.convention`): the first
  Robotiq driver angle / 0.824033 as the gripper, prompt lower-cased; the first 8 actions of
  each chunk run as joint targets, the gripper thresholded at 0.5.
* ``droid`` (``policy=pi0_droid``): openpi's DROID joint-velocity checkpoints (``pi0_droid``,
  ``pi0_fast_droid``, ``pi05_droid``): our native observation; the first 8 actions of each chunk
  (openpi's DROID client's open-loop horizon) are velocities integrated over the policy step.

The Python defaults below are the ``molmospaces`` preset; the presets themselves are the yaml files.
"""

from __future__ import annotations

from pathlib import PurePosixPath
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from molmo_lerobot.features import FeatureMap, is_wrist
from molmo_lerobot.policies.convention import ConventionName
from molmo_lerobot.policies.image_ops import resize_with_pad_pil

EXTERIOR = "observation/exterior_image_1_left"
WRIST = "observation/wrist_image_left"
JOINTS = "observation/joint_position"
GRIPPER = "observation/gripper_position"
PROMPT = "prompt"
ACTIONS = "actions"
#: DROID's joint state and action: a Franka's move groups in its order (its 8 values are our ``action`` feature)
DROID = FeatureMap.build({"arm": 7, "gripper": 1})
#: openpi's DROID checkpoints that output joint velocities (their ``*_jointpos`` twins output positions)
VELOCITY_CHECKPOINTS = frozenset({"pi0_droid", "pi0_fast_droid", "pi05_droid"})


class GripperConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")

    obs_open: float = 0.0       # observed gripper joint value sent as 0 (open) …
    obs_closed: float = 0.824033  # … and as 1 (closed); clipped to [0, 1]
    binarize: bool = True
    threshold: float = 0.5
    invert: bool = False


class CameraConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")

    #: a camera name, or candidates of which the first present is used; None: guessed from the names
    exterior: str | list[str] | None = None
    wrist: str | list[str] | None = None


class DroidConfig(BaseModel):
    """How our observations and actions map onto DROID's (defaults: the ``molmospaces`` preset)."""

    model_config = ConfigDict(extra="ignore")

    convention: ConventionName = "molmospaces"
    cameras: CameraConfig = Field(default_factory=CameraConfig)
    image_size: int = Field(default=224, ge=8)
    lowercase_prompt: bool = True
    action_mode: Literal["joint_velocity", "joint_position"] = "joint_position"
    velocity_scale: float = 1.0
    max_joint_delta: float | None = Field(default=None, gt=0)
    open_loop_horizon: int | None = Field(default=8, ge=1)
    action_dim: int = Field(default=8, ge=8)
    gripper: GripperConfig = Field(default_factory=GripperConfig)


def _first_present(wanted: str | list[str], available: list[str]) -> str | None:
    return next((c for c in ([wanted] if isinstance(wanted, str) else wanted) if c in available), None)


def pick_cameras(cameras: CameraConfig, available: list[str]) -> tuple[str, str]:
    """(exterior, wrist) camera names; unset ones are guessed from the names (``*wrist*``)."""
    if cameras.wrist:
        wrist = _first_present(cameras.wrist, available)
    else:
        wrist = next((c for c in available if is_wrist(c)), None)
    if cameras.exterior:
        exterior = _first_present(cameras.exterior, available)
    else:
        exterior = next((c for c in sorted(available) if c != wrist and not is_wrist(c)), None)
    for role, name in (("exterior", exterior), ("wrist", wrist)):
        if name is None:
            wanted = getattr(cameras, role)
            raise KeyError(
                f"pi0 needs a {role} camera: {f'policy.cameras.{role}={wanted!r}' if wanted else 'none found'} is not "
                f"among the observation's {sorted(available)} (set policy.cameras.{role}=<camera>)"
            )
    return exterior, wrist  # type: ignore[return-value]


def droid_request(images: dict[str, np.ndarray], qpos: dict[str, Any], prompt: str, cfg: DroidConfig) -> dict[str, Any]:
    """The DROID request: letterboxed uint8 images, 7 arm joints, the gripper in [0, 1], the prompt.

    ``images`` and ``qpos`` are the policy's view of the observation in ``cfg.convention``; the
    gripper value sent is its first joint mapped by ``cfg.gripper.obs_open`` / ``obs_closed``.
    """
    exterior, wrist = pick_cameras(cfg.cameras, list(images))
    if "arm" not in qpos or "gripper" not in qpos:
        raise KeyError(f"pi0 needs qpos 'arm' (7) and 'gripper'; observation has {sorted(qpos)}")
    arm = np.asarray(qpos["arm"], dtype=np.float64).reshape(-1)
    if arm.shape != (7,):
        raise ValueError(f"pi0 needs 7 arm joint positions, observation qpos['arm'] has shape {arm.shape}")
    g = float(np.asarray(qpos["gripper"], dtype=np.float64).reshape(-1)[0])
    span = cfg.gripper.obs_closed - cfg.gripper.obs_open
    g = float(np.clip((g - cfg.gripper.obs_open) / span if span else g, 0.0, 1.0))
    size = cfg.image_size
    return {
        EXTERIOR: resize_with_pad_pil(images[exterior], size, size),
        WRIST: resize_with_pad_pil(images[wrist], size, size),
        JOINTS: arm,
        GRIPPER: np.array([g], dtype=np.float64),
        PROMPT: prompt.lower() if cfg.lowercase_prompt else prompt,
    }


def droid_actions(raw: Any, arm_qpos: np.ndarray, cfg: DroidConfig, dt_s: float, source: str) -> dict[str, np.ndarray]:
    """(H, 8) DROID actions -> our chunk ``{"arm": (H, 7) joint targets, "gripper": (H, 1) in [0, 1]}``.

    The gripper is thresholded in the answer's own float type, as MolmoSpaces' ``PI_Policy`` compares
    it: a float32 0.3 is not above a threshold of 0.3 (in float64 it is, by 1.2e-8)."""
    received = np.asarray(raw).dtype
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
    parts = DROID.split_action(actions[:, : DROID.action_dim])
    joints, grip = parts["arm"], parts["gripper"][:, 0]
    if cfg.action_mode == "joint_velocity":
        deltas = joints * cfg.velocity_scale * dt_s
        if cfg.max_joint_delta is not None:
            deltas = np.clip(deltas, -cfg.max_joint_delta, cfg.max_joint_delta)
        arm = np.asarray(arm_qpos, dtype=np.float64).reshape(1, 7) + np.cumsum(deltas, axis=0)
    else:
        arm = joints
    if cfg.gripper.invert:
        grip = 1.0 - grip
    if cfg.gripper.binarize:
        own = grip.astype(received) if received.kind == "f" else grip  # float64 -> float32 -> float64 is exact
        grip = (own > own.dtype.type(cfg.gripper.threshold)).astype(np.float64)
    else:
        grip = np.clip(grip, 0.0, 1.0)
    return {"arm": arm, "gripper": grip[:, None]}


def check_checkpoint(name: str | None, action_mode: str) -> None:
    """Refuse an openpi checkpoint name whose action space is not ``action_mode`` (one line, the fix)."""
    if not name:
        return
    parts = [p for p in PurePosixPath(name.replace("\\", "/")).parts if p not in ("/", "")]
    if action_mode == "joint_position" and any(p in VELOCITY_CHECKPOINTS for p in parts):
        raise ValueError(f"checkpoint {name!r} is an openpi DROID joint-velocity checkpoint but this pi0 preset "
                         "applies absolute joint targets (MolmoSpaces' pi0 eval config): use policy=pi0_droid")
    if action_mode == "joint_velocity" and any("jointpos" in p for p in parts):
        raise ValueError(f"checkpoint {name!r} outputs joint positions but this pi0 preset integrates joint "
                         "velocities (openpi's DROID): use policy=pi0_molmospaces")
