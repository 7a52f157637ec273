import numpy as np
import pytest

from molmo_lerobot.runner.plan import resolve_horizon
from molmo_lerobot.runner.rollout import ActionError, split_actions

GROUPS = {"arm": 7, "gripper": 1}


def test_omitted_group_and_done():
    """A left-out move group holds (absent from the step); ``done`` marks a step (a bool: the chunk's last)."""
    steps = split_actions({"arm": np.zeros((3, 7)), "done": True}, GROUPS, "p")
    assert [set(s) for s in steps] == [{"arm"}, {"arm"}, {"arm", "done"}]
    steps = split_actions({"gripper": np.ones((2, 1)), "done": [True, False]}, GROUPS, "p")
    assert [s.get("done", False) for s in steps] == [True, False]
    assert split_actions({"done": True}, GROUPS, "p") == [{"done": True}]


def test_single_action_and_chunk():
    one = split_actions({"arm": np.zeros(7), "gripper": [1.0]}, GROUPS, "p")
    assert len(one) == 1 and one[0]["arm"].shape == (7,)
    chunk = split_actions({"arm": np.zeros((5, 7)), "gripper": np.ones((5, 1))}, GROUPS, "p")
    assert len(chunk) == 5 and chunk[4]["gripper"].shape == (1,)


@pytest.mark.parametrize(
    ("out", "needle"),
    [
        ({"arm": np.zeros(6), "gripper": [0.0]}, "'arm' with shape (6,), expected (7,) or (H, 7)"),
        ({}, "returned no move group"),
        ({"arm": np.zeros(7), "gripper": [0.0], "base": [0.0]}, "unknown move groups ['base']"),
        ({"arm": np.zeros((2, 7)), "done": [True, False, True]}, "'done'"),
        ({"arm": np.full(7, np.nan), "gripper": [0.0]}, "non-finite value in 'arm' (step 0, index 0)"),
        ({"arm": np.zeros((3, 7)), "gripper": np.zeros((2, 1))}, "chunks of different lengths"),
        ([0.0] * 8, "returned list, expected a dict"),
        ({"arm": ["a"] * 7, "gripper": [0.0]}, "non-numeric 'arm'"),
    ],
)
def test_bad_actions_are_named(out, needle):
    with pytest.raises(ActionError) as err:
        split_actions(out, GROUPS, "mypolicy")
    assert "mypolicy" in str(err.value) and needle in str(err.value)


class _Spec:
    task_horizon_sec = None


def test_horizon_resolution_order():
    spec = _Spec()
    assert resolve_horizon(None, spec, 20.0, 66.0) == 303  # pick default ≈ 303 steps
    assert resolve_horizon(None, spec, 40.0, 66.0) == 606
    spec.task_horizon_sec = 10.0
    assert resolve_horizon(None, spec, 20.0, 66.0) == 152
    assert resolve_horizon(50, spec, 20.0, 66.0) == 50
