"""The random policy (a policy plugin): a baseline that should essentially never succeed.

Each chunk moves the arm to a random joint target near the current pose (uniform within
``scale`` radians per joint) and sets the gripper to a random command; a move group whose actions
are deltas (an env suite's, named in ``EpisodeContext.extra["delta_groups"]``: LIBERO's 7-D delta
end-effector command) gets a random delta within ``scale`` instead, and one whose actions are targets
within a box (``extra["action_bounds"]``: PushT's 2-D target position in its workspace) a uniform draw
from that box. Draws come from a generator seeded by the episode seed, so episodes replay exactly.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Annotated, Any

import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.options import bounded, validate_group
from molmo_lerobot.policies.base import (
    MAX_CHUNK,
    Action,
    EpisodeContext,
    Observation,
    Policy,
    PolicyOptions,
    PolicyType,
)


class RandomOptions(PolicyOptions):
    """``policy=random``'s options."""

    name: str = "random"
    #: radians per joint around the current pose (at most a half turn); a delta group's bound
    scale: Annotated[int | float, bounded(0.0, math.pi, integer=False)] = 0.15
    #: policy steps per action chunk
    chunk: Annotated[int, bounded(1, MAX_CHUNK, integer=True)] = 8


class RandomPolicy(Policy):
    """Random joint targets near the current pose and a random gripper (:class:`RandomOptions`)."""

    needs_images = False

    def __init__(self, config: Mapping[str, Any]) -> None:
        options = validate_group("policy", RandomOptions, config)
        self.scale, self.chunk = float(options.scale), options.chunk
        self.rng = np.random.default_rng(0)
        self.move_groups: dict[str, int] = {}
        self.delta_groups: frozenset[str] = frozenset()
        self.bounds: dict[str, tuple[float, float]] = {}

    def reset(self, ctx: EpisodeContext) -> None:
        self.rng = np.random.default_rng(ctx.seed)
        self.move_groups = dict(ctx.move_groups)
        self.delta_groups = frozenset(ctx.extra.get("delta_groups", ()))
        self.bounds = {g: (float(lo), float(hi)) for g, (lo, hi) in ctx.extra.get("action_bounds", {}).items()}

    def act(self, obs: Observation) -> Action:
        out: Action = {}
        for group, dim in self.move_groups.items():
            if group in self.delta_groups:
                goal = self.rng.uniform(-self.scale, self.scale, dim)
            elif group in self.bounds:
                goal = self.rng.uniform(*self.bounds[group], dim)
            elif group == "gripper":
                goal = self.rng.uniform(0.0, 1.0, dim)
            else:
                goal = np.asarray(obs["qpos"][group], dtype=np.float64) + self.rng.uniform(-self.scale, self.scale, dim)
            out[group] = np.repeat(goal[None], self.chunk, axis=0)
        return out


@hookimpl
def molmo_policies() -> list[PolicyType]:
    return [PolicyType(name="random", factory=RandomPolicy, description="random joint targets near the current pose",
                       options=RandomOptions)]
