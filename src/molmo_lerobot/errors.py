"""The errors of molmo_lerobot, and whose failure one is: the episode's, or the machinery's around it.

Every exception class of the package derives from :class:`MolmoError` (next to the builtin base
its callers catch: ``ValueError``, ``LookupError``, ``OSError`` …), so ``except MolmoError``
catches what this package raises on purpose and nothing else.

An episode error is part of the result (the policy raised, the physics diverged) and stays
when a run is resumed. An infrastructure failure says nothing about the policy: it is
recorded with ``error_kind="infrastructure"`` and ``resume=true`` runs the episode again.
"""

from __future__ import annotations

import errno
import traceback
from pathlib import Path
from typing import ClassVar

EPISODE, INFRASTRUCTURE = "episode", "infrastructure"

#: ``OSError`` numbers that mean the machine, not the episode, failed: a full disk or quota,
#: a read-only or failing file system
MACHINE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EIO})


class MolmoError(Exception):
    """Base of every molmo_lerobot error.

    The message is one line that names what it is about (the file, episode, field or option),
    says what is wrong and, where there is a remedy, what to do: ``"<where>: <what>; <what to do>"``.
    An error that gathers several problems puts one per line (``molmo-eval`` prints each as one
    ``error:`` line)."""

    #: whose failure it is when it ends an episode (:func:`error_kind`)
    kind: ClassVar[str] = EPISODE


class InfrastructureError(MolmoError, RuntimeError):
    """A failure of what runs the episode, not of the episode (e.g. the policy server is gone)."""

    kind = INFRASTRUCTURE


class RunError(MolmoError, RuntimeError):
    """The run cannot start or continue; the message says why and what to do."""


class ExportError(RunError):
    """An export step failed (merging the dataset shards, a recorder's finalizer, the report); a
    run's score, written before any export, stands."""


def error_kind(exc: BaseException) -> str:
    """:data:`INFRASTRUCTURE` for an error whose :attr:`MolmoError.kind` says so (an :class:`InfrastructureError`,
    a link planted where we write: ``fileio.UnsafePathError``) or a full/failing disk, else :data:`EPISODE`."""
    if (isinstance(exc, MolmoError) and exc.kind == INFRASTRUCTURE) or (
            isinstance(exc, OSError) and exc.errno in MACHINE_ERRNOS):
        return INFRASTRUCTURE
    return EPISODE


def describe(exc: BaseException) -> str:
    """One line: exception type, the first line of its message and where it was raised."""
    tb = traceback.extract_tb(exc.__traceback__)
    where = f" (at {Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0] if text else ''}{where}"
