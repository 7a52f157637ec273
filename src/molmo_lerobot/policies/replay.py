"""The replay policy (a policy plugin): plays a fixed action sequence, open loop.

``policy=replay policy.actions=<file.npy>`` with an array of shape ``(T, n)``: one row per policy
step, the move groups concatenated in the robot's order (the ``action`` feature of our datasets
and the Gymnasium env's action). Past ``T`` the last row is held. Useful to replay a recorded
dataset's actions, or the same actions through ``molmo-eval`` and the Gymnasium env.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import Field

from molmo_lerobot import hookimpl
from molmo_lerobot.features import split
from molmo_lerobot.options import rule, validate_group
from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyOptions, PolicyType


class ReplayOptions(PolicyOptions):
    """``policy=replay``'s options."""

    name: str = "replay"
    #: the .npy file of shape (T, n) played row by row (no default: every run names its own)
    actions: Annotated[str, rule(lambda v: isinstance(v, str) and v != "",
                                 "{key}: missing; give policy.actions=<file.npy> (an array of shape (T, n))")
                       ] = Field(default=None, validate_default=True)


class ReplayPolicy(Policy):
    """Rows of ``policy.actions`` in order, split into move groups."""

    needs_images = False

    def __init__(self, config: Mapping[str, Any]) -> None:
        path = validate_group("policy", ReplayOptions, config).actions
        try:
            actions = np.load(Path(path).expanduser(), allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ValueError(f"policy.actions={path}: cannot load a .npy array ({exc})") from None
        if actions.ndim != 2 or not len(actions) or not np.all(np.isfinite(actions)):
            raise ValueError(f"policy.actions={path}: expected a finite array of shape (T, n), got {actions.shape}")
        self.actions = actions.astype(np.float64)
        self.move_groups: dict[str, int] = {}
        self.t = 0

    def reset(self, ctx: EpisodeContext) -> None:
        self.move_groups = dict(ctx.move_groups)
        if sum(self.move_groups.values()) != self.actions.shape[1]:
            raise ValueError(f"policy.actions has {self.actions.shape[1]} columns, the robot's move groups "
                             f"{self.move_groups} need {sum(self.move_groups.values())}")
        self.t = 0

    def act(self, obs: Observation) -> Action:
        row = self.actions[min(self.t, len(self.actions) - 1)]
        self.t += 1
        return split(row, self.move_groups)


@hookimpl
def molmo_policies() -> list[PolicyType]:
    return [PolicyType(name="replay", factory=ReplayPolicy, description="a fixed action sequence (policy.actions=…)",
                       options=ReplayOptions)]
