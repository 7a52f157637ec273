"""``policy=pi0_libero``: openpi's LIBERO checkpoints (``pi0_libero``, ``pi0_fast_libero``, ``pi05_libero``) on
``benchmark=libero_*``, through an openpi server (``serve_policy``) or ``molmo-serve``.

The request is what openpi's LIBERO client sends and its ``LiberoInputs`` reads: ``observation/image`` (the
agent view) and ``observation/wrist_image``, each turned 180° as LIBERO's renders are for training (the suite's
observation already is) and letterboxed to 224² uint8 (PIL bilinear, black padding); ``observation/state``, the
8-D end-effector position, axis-angle and finger positions; ``prompt``, the task's instruction as written. The
answer's ``actions`` are (H, 7) delta end-effector commands (``LiberoOutputs``); the first ``open_loop_horizon``
(openpi's ``replan_steps``, 5) run per request. openpi renders LIBERO at 256² (``benchmark.image_size=256``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from molmo_lerobot.options import validate_group
from molmo_lerobot.policies.base import Action, EpisodeContext, Observation
from molmo_lerobot.policies.image_ops import resize_with_pad_pil
from molmo_pi0.policy import OpenpiClientPolicy, Pi0Config

IMAGE = "observation/image"
WRIST = "observation/wrist_image"
STATE = "observation/state"
PROMPT = "prompt"
#: the LIBERO suite's policy observation (molmo_lerobot.suites.libero): cameras, its one move group and sizes
CAMERAS = {IMAGE: "image", WRIST: "image2"}
MOVE_GROUP, STATE_DIM, ACTION_DIM = "eef", 8, 7


def libero_request(obs: Observation, prompt: str, size: int) -> dict[str, Any]:
    """openpi's LIBERO request of a LIBERO suite observation."""
    images = obs.get("images") or {}
    missing = [cam for cam in CAMERAS.values() if cam not in images]
    state = np.asarray((obs.get("qpos") or {}).get(MOVE_GROUP, ()), dtype=np.float64).reshape(-1)
    if missing or state.shape != (STATE_DIM,):
        raise ValueError(f"policy=pi0_libero needs a LIBERO observation (cameras image, image2 and the 8-D "
                         f"qpos[{MOVE_GROUP!r}]; benchmark=libero_*): got cameras {sorted(images)}, "
                         f"state {state.shape}")
    return {**{key: resize_with_pad_pil(images[cam], size, size) for key, cam in CAMERAS.items()},
            STATE: state, PROMPT: prompt}


def libero_actions(raw: Any, open_loop_horizon: int | None, source: str) -> dict[str, np.ndarray]:
    """The answer's (H, 7) actions -> our chunk ``{"eef": (h, 7)}``, its first ``open_loop_horizon``."""
    actions = np.asarray(raw, dtype=np.float64)
    if actions.ndim == 1:
        actions = actions[None]
    if actions.ndim != 2 or actions.shape[0] < 1 or actions.shape[1] < ACTION_DIM:
        raise ValueError(f"{source}: 'actions' has shape {actions.shape}, expected (H, {ACTION_DIM})")
    actions = actions[:open_loop_horizon, :ACTION_DIM] if open_loop_horizon else actions[:, :ACTION_DIM]
    if not np.isfinite(actions).all():
        step = int(np.argwhere(~np.isfinite(actions))[0][0])
        raise ValueError(f"{source}: 'actions' has a non-finite value at step {step}")
    return {MOVE_GROUP: actions}


class Pi0LiberoPolicy(OpenpiClientPolicy):
    """One openpi connection per worker; LIBERO requests, 7-D chunks."""

    def __init__(self, cfg: dict[str, Any]) -> None:
        self.cfg = validate_group("policy", Pi0Config, cfg)
        if self.cfg.path:
            raise ValueError("policy=pi0_libero talks to an openpi server (policy.host, policy.port); a LeRobot "
                             f"LIBERO checkpoint ({self.cfg.path}) runs with policy=lerobot policy.path=…")
        self._open_client()

    def reset(self, ctx: EpisodeContext) -> None:
        if dict(ctx.move_groups) != {MOVE_GROUP: ACTION_DIM}:
            raise ValueError(f"policy=pi0_libero plays LIBERO episodes (benchmark=libero_*, move group "
                             f"{MOVE_GROUP!r} of {ACTION_DIM}); this episode's move groups are {dict(ctx.move_groups)}")
        super().reset(ctx)

    def act(self, obs: Observation) -> Action:
        assert self._ctx is not None, "reset() must be called before act()"
        prompt = obs.get("prompt") or self._ctx.prompt
        request = libero_request(obs, prompt.lower() if self.cfg.lowercase_prompt else prompt, self.cfg.image_size)
        return libero_actions(self._infer_actions(request), self.cfg.open_loop_horizon,
                              f"policy server {self.client.uri}")
