"""The deterministic policies of the LIBERO parity test, shared by both sides (plain numpy, so the reference
script in the LIBERO venv imports this file too): an action is a function of (episode seed, step) only."""

from __future__ import annotations

import numpy as np


def random_action(seed: int, step: int) -> np.ndarray:
    """A seeded uniform random 7-D action in [-1, 1] (float32, as a LeRobot policy's tensor)."""
    return np.random.default_rng([seed, step]).uniform(-1.0, 1.0, 7).astype(np.float32)


def replay_action(seed: int, step: int) -> np.ndarray:
    """A fixed open-loop action sequence (the same for every episode): slow sweeps, the gripper closing
    half-way through and reopening."""
    t = float(step)
    xyz = [0.6 * np.sin(0.07 * t), 0.5 * np.cos(0.05 * t), -0.4 * np.sin(0.03 * t)]
    rot = [0.1 * np.sin(0.11 * t), 0.0, -0.1 * np.cos(0.13 * t)]
    grip = 1.0 if 20 <= step % 60 < 45 else -1.0
    return np.asarray([*xyz, *rot, grip], dtype=np.float32)


POLICIES = {"random": random_action, "replay": replay_action}
