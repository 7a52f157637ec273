"""molmo-serve's native request format, checked against fixed bounds before a policy sees it.

A client sends the observation dict of :mod:`molmo_lerobot.policies.base` as is, and
``{"endpoint": "reset", episode_index, seed, prompt, move_groups, policy_dt_s}`` at the start
of each episode. Everything a client can ask for is bounded here (number and size of move
groups, image and array sizes, prompt length, numbers in range), so a tiny request can never
make the server build a huge reply: a policy sizes its action by ``move_groups``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.policies.base import EpisodeContext

DEFAULT_MOVE_GROUPS = {"arm": 7, "gripper": 1}
MAX_MOVE_GROUPS = 16
MAX_GROUP_DIM = 256
MAX_CAMERAS = 16
MAX_IMAGE_SIDE = 4096
MAX_PROMPT_CHARS = 8192
MAX_POLICY_DT_S = 60.0
RESET_KEYS = {"endpoint", "episode_index", "seed", "prompt", "move_groups", "policy_dt_s"}


class RequestError(MolmoError, ValueError):
    """A client's request cannot be served (the message is sent back to it)."""


def _int(value: Any, field: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= int(value) <= hi:
        raise RequestError(f"{field} must be an integer in [{lo}, {hi}], got {_show(value)}")
    return int(value)


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def move_groups(value: Any) -> dict[str, int]:
    """``{group: dim}`` with at most :data:`MAX_MOVE_GROUPS` groups of 1..:data:`MAX_GROUP_DIM` each."""
    if value is None:
        return dict(DEFAULT_MOVE_GROUPS)
    if not isinstance(value, dict) or not value:
        raise RequestError(f"move_groups must be a non-empty map of group name to dimension, got {_show(value)}")
    if len(value) > MAX_MOVE_GROUPS:
        raise RequestError(f"move_groups has {len(value)} groups, at most {MAX_MOVE_GROUPS} are allowed")
    out = {}
    for name, dim in value.items():
        if not isinstance(name, str) or not 0 < len(name) <= 64:
            raise RequestError(f"move_groups: group names must be strings of 1-64 characters, got {_show(name)}")
        out[name] = _int(dim, f"move_groups[{name!r}]", 1, MAX_GROUP_DIM)
    return out


def episode_context(request: dict[str, Any]) -> EpisodeContext:
    """An episode context from a reset message (or a first observation); never privileged state."""
    prompt = request.get("prompt", "")
    if not isinstance(prompt, str) or len(prompt) > MAX_PROMPT_CHARS:
        raise RequestError(f"prompt must be a string of at most {MAX_PROMPT_CHARS} characters")
    dt = request.get("policy_dt_s", 0.066)
    if (isinstance(dt, bool) or not isinstance(dt, (int, float))
            or not (0 < dt <= MAX_POLICY_DT_S and math.isfinite(dt))):
        raise RequestError(f"policy_dt_s must be a number in (0, {MAX_POLICY_DT_S:g}], got {_show(dt)}")
    is_reset = request.get("endpoint") == "reset"
    return EpisodeContext(
        spec=None,  # remote clients never share their episode spec
        episode_index=_int(request.get("episode_index", -1), "episode_index", -1, 2**63 - 1),
        seed=_int(request.get("seed", 0), "seed", 0, 2**63 - 1),
        prompt=prompt,
        move_groups=move_groups(request.get("move_groups")),
        policy_dt_s=float(dt),
        extra={k: v for k, v in request.items() if k not in RESET_KEYS} if is_reset else {},
    )


def _array(value: Any, field: str, ndim: int, max_len: int, kinds: str) -> None:
    if not isinstance(value, (np.ndarray, list, tuple)):
        raise RequestError(f"{field} must be an array, got {type(value).__name__}")
    arr = np.asarray(value) if not isinstance(value, np.ndarray) else value
    if arr.ndim != ndim or arr.dtype.kind not in kinds:
        raise RequestError(f"{field} must be a {ndim}-d numeric array, got shape {arr.shape} dtype {arr.dtype}")
    if any(s > max_len for s in arr.shape[:2]):
        raise RequestError(f"{field} has shape {arr.shape}; at most {max_len} per axis")


def check_observation(obs: dict[str, Any]) -> None:
    """Bound the native observation fields (other keys pass: they are bounded by the message size)."""
    for key in ("qpos", "qvel"):
        groups = obs.get(key)
        if groups is None:
            continue
        if not isinstance(groups, dict) or len(groups) > MAX_MOVE_GROUPS:
            raise RequestError(f"{key} must be a map of at most {MAX_MOVE_GROUPS} move groups")
        for name, value in groups.items():
            _array(value, f"{key}[{name!r}]", 1, MAX_GROUP_DIM, "biuf")
    for key, ndim, kinds in (("images", 3, "u"), ("depth", 2, "f")):
        cams = obs.get(key)
        if cams is None:
            continue
        if not isinstance(cams, dict) or len(cams) > MAX_CAMERAS:
            raise RequestError(f"{key} must be a map of at most {MAX_CAMERAS} cameras")
        for name, value in cams.items():
            _array(value, f"{key}[{name!r}]", ndim, MAX_IMAGE_SIDE, kinds)
            if key == "images" and np.shape(value)[2] not in (1, 3, 4):
                raise RequestError(f"images[{name!r}] has {np.shape(value)[2]} channels, expected 1, 3 or 4")
    if "tcp_pose" in obs:
        _array(obs["tcp_pose"], "tcp_pose", 1, 16, "biuf")
    prompt = obs.get("prompt")
    if prompt is not None and (not isinstance(prompt, str) or len(prompt) > MAX_PROMPT_CHARS):
        raise RequestError(f"prompt must be a string of at most {MAX_PROMPT_CHARS} characters")


def action_nbytes(action: Any) -> int:
    """Bytes the arrays of an action dict will take on the wire (checked before encoding)."""
    if not isinstance(action, dict):
        raise TypeError(f"policy returned {type(action).__name__}, expected a dict of arrays")
    return sum(np.asarray(v).nbytes if isinstance(v, (np.ndarray, list, tuple)) else 64 for v in action.values())
