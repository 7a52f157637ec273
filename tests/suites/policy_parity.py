"""Our side of the policy-parity tests: a checkpoint as ``molmo-eval policy=lerobot policy.path=…`` builds it (the
composed config's defaults, ``make_policy``), played on a suite session by our rollout loop, remembering the action
handed to the env at every step; and the comparison with ``lerobot_policy_reference.py``'s episodes."""

from __future__ import annotations

from importlib.util import find_spec
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from molmo_lerobot.config import compose
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import Policy
from molmo_lerobot.policies.factory import make_policy
from molmo_lerobot.recording import Recorder
from molmo_lerobot.runner.rollout import rollout

#: LeRobot's diffusion policy needs its ``diffusion`` extra (``diffusers``, in this project's ``test`` extra)
needs_diffusers = pytest.mark.skipif(find_spec("diffusers") is None, reason="diffusers not installed")


class Actions(Recorder):
    """Every step's action of one move group, as the rollout hands it to the recorders (what the env was given)."""

    wants_images = False

    def __init__(self, group: str) -> None:
        self.group, self.actions = group, []

    def start_episode(self, info) -> None:
        self.actions = []

    def record_step(self, obs, action, reward, success, done) -> None:
        self.actions.append(np.asarray(action[self.group], dtype=np.float32).tolist())

    def end_episode(self, result) -> None:
        pass


def molmo_policy(checkpoint: Path) -> Policy:
    """``policy=lerobot policy.path=<checkpoint> policy.device=cpu`` with every other option at its default."""
    config = compose(["policy=lerobot", f"policy.path={checkpoint}", "policy.device=cpu"])
    return make_policy(Plugins(), dict(config["policy"]))


def play_session(session: Any, policy: Policy, group: str) -> dict[str, Any]:
    """One opened suite session played by our rollout loop: its success, seed, steps and every step's action."""
    actions = Actions(group)
    actions.start_episode(None)
    result = rollout(session, policy, [actions], "parity")
    return {"success": result.success, "seed": result.seed, "steps": result.steps, "actions": actions.actions}


def assert_same_episodes(ours: list[dict[str, Any]], theirs: list[dict[str, Any]], where: str) -> None:
    """Outcome, seed and step count equal per episode, and every step's action bit for bit."""
    assert len(ours) == len(theirs), where
    for k, (o, t) in enumerate(zip(ours, theirs, strict=True)):
        label = f"{where} episode {k}"
        assert (o["success"], o["seed"], o["steps"]) == (t["success"], t["seed"], t["steps"]), label
        for step, (a, b) in enumerate(zip(o["actions"], t["actions"], strict=True)):
            diff = float(np.abs(np.subtract(a, b)).max())
            assert a == b, f"{label} step {step}: action {a}, lerobot-eval's {b} (max difference {diff:.3g})"
