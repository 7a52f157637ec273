"""Timing semantics: the physics timestep comes from sim_dt, a policy step is ticks x substeps."""

from __future__ import annotations

import numpy as np
import pytest

from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing


def test_defaults_match_molmospaces():
    t = Timing()
    assert (t.policy_dt_ms, t.ctrl_dt_ms, t.sim_dt_ms) == (66.0, 2.0, 2.0)
    assert (t.ctrl_ticks, t.substeps) == (33, 1)


@pytest.mark.parametrize(("policy", "ctrl", "sim", "field"), [
    (66.0, 4.0, 2.0, "policy_dt_ms / ctrl_dt_ms"),
    (66.0, 2.0, 0.75, "ctrl_dt_ms / sim_dt_ms"),
    (66.0, 0.0, 2.0, "ctrl_dt_ms"),
    (float("nan"), 2.0, 2.0, "policy_dt_ms"),
    (1.0, 2.0, 2.0, "policy_dt_ms / ctrl_dt_ms"),
])
def test_bad_timing_is_rejected(policy, ctrl, sim, field):
    with pytest.raises(ValueError, match=field.replace("/", r"\/").replace(" ", r"\s")):
        Timing(policy, ctrl, sim)


def test_timestep_and_substeps_from_timing(pick_spec, run):
    timing = Timing(policy_dt_ms=60.0, ctrl_dt_ms=4.0, sim_dt_ms=1.0)
    env = build_env(pick_spec, timing, run)
    try:
        assert env.model.opt.timestep == pytest.approx(0.001)  # not the robot XML's 0.002
        env.reset(0)
        obs = env.observe(images=False)
        env.step({"arm": obs["qpos"]["arm"], "gripper": np.zeros(1)})
        assert env.data.time == pytest.approx(0.060)
        assert timing.ctrl_ticks * timing.substeps == 60
    finally:
        env.close()


def test_controller_ticks_interpolate_targets(pick_spec, run):
    env = build_env(pick_spec, Timing(), run)
    try:
        env.reset(0)
        q0 = env.robot.targets(env.data, "arm")
        goal = q0 + 0.1
        env.step({"arm": goal, "gripper": np.zeros(1)})
        assert np.allclose(env.robot.targets(env.data, "arm"), goal)  # reached at the last tick
        assert np.all(np.abs(env.robot.qpos(env.data, "arm") - goal) < 0.1)  # the arm moved towards it
    finally:
        env.close()
