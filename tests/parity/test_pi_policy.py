"""``policy=pi0`` presets against MolmoSpaces' ``PI_Policy``: the same observations and server answers
give the same requests and the same joint targets and gripper commands, step by step.

The parity tests run their policy in the parity venv (pi_policy_theirs.py); the default-suite test
compares with what it applied when recorded (record_pi_policy.py -> pi_policy_expected.json), and a
parity test keeps that file equal to a fresh run of their code.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from pi_policy_scenario import (
    CASES,
    DT,
    Case,
    applied_ours,
    applied_theirs,
    chunks,
    differences,
    observations,
    run_ours,
)
from record_pi_policy import EXPECTED

from molmo_lerobot.config import compose

RECORDED = json.loads(EXPECTED.read_text())


@pytest.fixture(scope="module")
def their_run(theirs):
    from pi_policy_scenario import their_inputs

    return theirs.run("pi_policy_theirs:main", their_inputs(CASES))


@pytest.mark.parity
@pytest.mark.parametrize("case", sorted(CASES))
def test_preset_applies_what_their_pi_policy_applies(their_run, case):
    ours = applied_ours(run_ours(CASES[case]))
    assert differences(ours, applied_theirs(their_run, case)) == []


@pytest.mark.parity
def test_recorded_expectations_are_theirs_today(their_run):
    assert {name: applied_theirs(their_run, name) for name in CASES} == RECORDED["cases"]
    assert their_run["end_on_success"] == RECORDED["end_on_success"]


@pytest.mark.parametrize("case", ["binary", "continuous"])
def test_preset_applies_what_their_pi_policy_applied(case):
    """Default suite, no parity venv: against the recorded run of their code."""
    assert differences(applied_ours(run_ours(CASES[case])), RECORDED["cases"][case]) == []


def test_end_on_success_follows_the_preset():
    ends = {p: compose([f"policy={p}"])["end_on_success"] for p in ("pi0", "pi0_molmospaces", "pi0_droid", "scripted")}
    assert ends == {"pi0": RECORDED["end_on_success"], "pi0_molmospaces": RECORDED["end_on_success"],
                    "pi0_droid": False, "scripted": False}
    assert compose(["policy=pi0", "end_on_success=false"])["end_on_success"] is False


def test_droid_preset_is_not_their_convention():
    """policy=pi0_droid (openpi's velocity checkpoints) integrates the same answers instead: a deliberate difference."""
    case = Case({}, "pi0_droid")
    ours = run_ours(case)
    answers, obs = chunks(case.horizon), observations()
    first = np.asarray(obs[0]["qpos"]["arm"]) + np.cumsum(answers[0, :8, :7].astype(np.float64) * DT, axis=0)
    np.testing.assert_allclose(ours["arm"][:8], first, rtol=0, atol=1e-12)
    assert ours["requests"][0]["prompt"] == obs[0]["prompt"]  # not lower-cased
    assert differences(applied_ours(ours), RECORDED["cases"]["binary"]) != []
