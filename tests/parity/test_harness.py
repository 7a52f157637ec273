"""The parity harness itself: their venv answers, and a failure there surfaces here."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.parity


def test_their_venv_runs_molmo_spaces_pinned(theirs):
    got = theirs.run("theirs:versions")
    assert got["molmo-spaces"] == "0.2.9"
    assert got["mujoco"] == "3.5.0"
    assert got["python"].startswith("3.12.")


def test_a_failing_helper_raises_with_their_traceback(theirs):
    with pytest.raises(theirs.TheirError, match=r"AttributeError.*no_such_helper"):
        theirs.run("theirs:no_such_helper", {"x": np.arange(3.0), "label": "a"})
