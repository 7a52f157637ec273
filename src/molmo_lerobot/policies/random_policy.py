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
from typing import Any

import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.policies.base import (
    MAX_CHUNK,
    Action,
    EpisodeContext,
    Observation,
    Policy,
    PolicyType,
    option_problems,
)


class RandomPolicy(Policy):
    """Random joint targets near the current pose and a random gripper. Config: ``scale``, ``chunk``."""

    needs_images = False

    def __init__(self, config: dict[str, Any]) -> None:
        self.scale = float(config.get("scale", 0.15))
        self.chunk = int(config.get("chunk", 8))
        if self.scale < 0 or self.chunk < 1:
            raise ValueError("random policy: scale must be >= 0 and chunk >= 1")
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


def make_random(config: dict[str, Any]) -> RandomPolicy:
    return RandomPolicy(config)


def random_config_problems(config: dict[str, Any]) -> list[str]:
    """``scale`` (radians per joint, at most a half turn) and ``chunk`` bounded."""
    return option_problems(config, {"scale": (0.0, math.pi, False), "chunk": (1, MAX_CHUNK, True)})


@hookimpl
def molmo_policies() -> list[PolicyType]:
    return [PolicyType(name="random", factory=make_random, description="random joint targets near the current pose",
                       check=random_config_problems)]
