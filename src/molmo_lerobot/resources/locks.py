"""Inter-process file locks for the cache and install dirs, with a named owner and a clear stale-lock error.

A lock is a file below one of the roots, locked with ``filelock`` (reentrant within a thread: one
``FileLock`` per path) and created without following a link (:mod:`molmo_lerobot.fileio`); while held,
``<lock>.owner`` says which process on which host holds it, so a timeout can name it, or say that it is
gone (a stale lock, e.g. NFS after a killed container).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from collections.abc import Iterator
from pathlib import Path

from filelock import FileLock, Timeout

from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.resources.errors import StaleLockError


class FileLocks:
    """The locks below ``roots``; ``enabled=False`` (a worker reading a cache a leader filled) holds none."""

    def __init__(self, roots: tuple[Path | None, ...], *, enabled: bool = True, timeout: float = 600.0) -> None:
        self.roots = tuple(r for r in roots if r is not None)
        self.enabled, self.timeout = enabled, timeout
        self._pid = os.getpid()
        self._held: dict[str, FileLock] = {}

    def root_of(self, path: Path) -> Path:
        """The root ``path`` lies in: writes walk from there without following links."""
        root = next((r for r in self.roots if path.is_relative_to(r)), None)
        if root is None:
            raise ValueError(f"{path} is in none of {', '.join(map(str, self.roots))}")
        return root

    @contextlib.contextmanager
    def hold(self, path: Path) -> Iterator[None]:
        """Hold the lock file ``path`` (reentrant within a thread); :class:`StaleLockError` after the timeout."""
        if not self.enabled:
            yield
            return
        if os.getpid() != self._pid:  # FileLock objects inherited through fork must not be shared
            self._held, self._pid = {}, os.getpid()
        root = self.root_of(path)
        os.close(fileio.open_fd(path, os.O_RDWR | os.O_CREAT, root=root))  # FileLock would follow a link
        lock = self._held.setdefault(str(path), FileLock(str(path), timeout=self.timeout))
        try:
            lock.acquire()
        except Timeout:
            raise StaleLockError(lock_message(path, self.timeout)) from None
        owner = Path(f"{path}.owner")
        try:
            if lock.lock_counter == 1:
                atomic_write(owner, json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                                                "since": time.time()}), root=root)
            yield
        finally:
            if lock.lock_counter == 1:
                with contextlib.suppress(OSError):
                    fileio.remove(owner, root=root)
            lock.release()


def lock_message(path: Path, timeout: float) -> str:
    """Why ``path`` could not be locked: its owner (from ``<path>.owner``), or that the owner is gone."""
    owner = Path(f"{path}.owner")
    info = {}
    with contextlib.suppress(OSError, ValueError):
        info = json.loads(owner.read_text())
    pid, host = info.get("pid"), info.get("host")
    if pid and host == socket.gethostname() and not _pid_alive(pid):
        return (f"stale lock {path}: its owner (pid {pid}) is gone but the lock is still held "
                f"(e.g. NFS after a killed container); make sure no install runs, then delete {path}")
    who = f"pid {pid} on {host}" if pid else "an unknown process"
    return (f"timed out after {timeout:g}s waiting for lock {path} held by {who}; "
            f"if that process no longer exists, delete {path} and retry")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
