"""Errors of the resource manager: each message is one line naming the archive, path or lock."""

from __future__ import annotations

from molmo_lerobot.errors import MolmoError


class ResourceError(MolmoError, RuntimeError):
    """A resource could not be packed, fetched, installed or verified."""

    #: whether fetching the archive again may help (a download fault); False for what a retry repeats
    retryable: bool = True


class CorruptArchiveError(ResourceError):
    """An archive's size or sha256 does not match its manifest, or it cannot be decompressed."""


class UnsafeArchiveError(ResourceError):
    """An archive member would escape the extraction directory or is not a plain file/dir/link."""


class StaleLockError(ResourceError):
    """A lock could not be taken in time; the message names the holder and what to do."""


class RemoteNotFoundError(ResourceError):
    """The remote answered that a file does not exist (HTTP 404 or its equivalent)."""
