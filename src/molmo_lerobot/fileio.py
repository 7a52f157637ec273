"""Atomic file writes: a file is either its old content or its complete new content.

The new content goes to a uniquely named temporary file next to the target, which is
flushed and fsynced, renamed over the target, and then the directory is fsynced so that
the rename itself survives a crash. On any error the temporary file is removed and the
target is untouched. Files get the usual permissions (``0o666`` less the umask).
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any


def fsync_dir(path: str | os.PathLike) -> None:
    """Make renames and new entries in directory ``path`` durable."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """``with atomic_open(path, "wb") as f: ...``: ``path`` gets what was written, once the block succeeds."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, mode.replace("w", "x"), **kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_dir(path.parent)


def atomic_write(path: str | os.PathLike, data: str | bytes, *, parents: bool = False,
                 encoding: str = "utf-8") -> Path:
    """Replace ``path``'s content with ``data`` atomically and durably; return ``path``.

    ``parents=True`` creates missing parent directories first.
    """
    if parents:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    if isinstance(data, bytes):
        with atomic_open(path, "wb") as f:
            f.write(data)
    else:
        with atomic_open(path, "w", encoding=encoding) as f:
            f.write(data)
    return Path(path)
