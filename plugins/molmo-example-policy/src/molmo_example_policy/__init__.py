"""Example third-party plugin: a policy (a sine wave on every arm joint around the start pose) and a
benchmark pack (``benchmarks/example_pick``: two pick episodes on the procedural tabletop)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.packs import BenchmarkDir, benchmark_pack
from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyType


class SinePolicy(Policy):
    needs_images = False

    def __init__(self, cfg: dict[str, Any]) -> None:
        self.amplitude = float(cfg.get("amplitude", 0.1))
        self.period_s = float(cfg.get("period_s", 2.0))
        if self.period_s <= 0:
            raise ValueError(f"policy.period_s must be positive, got {self.period_s}")
        self._start: np.ndarray | None = None
        self._dt = 0.066

    def reset(self, ctx: EpisodeContext) -> None:
        self._start = None
        self._dt = ctx.policy_dt_s

    def act(self, obs: Observation) -> Action:
        arm = np.asarray(obs["qpos"]["arm"], dtype=np.float64)
        if self._start is None:
            self._start = arm.copy()
        t = int(obs.get("step", 0)) * self._dt
        offset = self.amplitude * np.sin(2 * np.pi * t / self.period_s)
        return {"arm": self._start + offset, "gripper": np.zeros(1)}


def make_sine_policy(cfg: dict[str, Any]) -> Policy:
    return SinePolicy(cfg)


@hookimpl
def molmo_policies() -> list[PolicyType]:
    return [PolicyType("example_sine", make_sine_policy, "example plugin: sine wave around the start pose")]


@hookimpl
def molmo_config_dirs() -> list[str]:
    return [str(Path(__file__).resolve().parent / "conf")]


@hookimpl
def molmo_benchmarks() -> list[BenchmarkDir]:
    return benchmark_pack(Path(__file__).resolve().parent / "benchmarks")
