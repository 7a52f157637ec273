"""The ``theirs`` fixture: MolmoSpaces' code in its own venv (see tests/parity/theirs.py)."""

from __future__ import annotations

import os

import pytest

try:
    import theirs as _theirs
except ImportError:  # tests/ imported as a package
    from tests.parity import theirs as _theirs


@pytest.fixture(scope="session")
def theirs():
    """The ``theirs`` module, once the parity venv is there.

    Without the venv the test skips, or fails under ``make parity`` (MOLMO_PARITY_REQUIRED=1).
    """
    if _theirs.python() is None:
        reason = f"no MolmoSpaces parity venv at {_theirs.VENV} (build it: make parity)"
        if os.environ.get(_theirs.REQUIRED_ENV) == "1":
            pytest.fail(reason)
        pytest.skip(reason)
    return _theirs
