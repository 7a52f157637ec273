"""Filesystem operations below a root that never follow a symlink.

Paths are walked one component at a time from a directory file descriptor opened with
``O_NOFOLLOW``, so a link — from the archive being written, from another archive of the
same version, or planted by anyone else — can never redirect a write outside the root.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from collections.abc import Iterator
from pathlib import Path, PurePosixPath

from molmo_lerobot.resources.errors import UnsafeArchiveError

_DIR = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC


@contextlib.contextmanager
def open_root(path: str | os.PathLike) -> Iterator[int]:
    """A directory fd on ``path`` (which must be a real directory, not a link)."""
    try:
        fd = os.open(path, _DIR)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.ENOTDIR):
            raise UnsafeArchiveError(f"{path} is a symlink or not a directory; refusing to write into it") from None
        raise
    try:
        yield fd
    finally:
        os.close(fd)


def lstat_at(dir_fd: int, name: str) -> os.stat_result | None:
    try:
        return os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
    except FileNotFoundError:
        return None


@contextlib.contextmanager
def parent_of(root_fd: int, rel: str, *, create: bool, where: str) -> Iterator[tuple[int, str]]:
    """``(fd of rel's parent dir, rel's last component)``; missing dirs are made when ``create``.

    Raises :class:`UnsafeArchiveError` naming the component when one is a symlink or a file.
    """
    parts = PurePosixPath(rel).parts
    fd = os.dup(root_fd)
    try:
        for i, part in enumerate(parts[:-1]):
            try:
                nfd = os.open(part, _DIR, dir_fd=fd)
            except FileNotFoundError:
                if not create:
                    raise
                with contextlib.suppress(FileExistsError):
                    os.mkdir(part, 0o755, dir_fd=fd)
                nfd = _open_dir(fd, part, parts, i, rel, where)
            except OSError as exc:
                if exc.errno not in (errno.ELOOP, errno.ENOTDIR):
                    raise
                nfd = _open_dir(fd, part, parts, i, rel, where)
            os.close(fd)
            fd = nfd
        yield fd, parts[-1]
    finally:
        os.close(fd)


def _open_dir(fd: int, part: str, parts: tuple, i: int, rel: str, where: str) -> int:
    try:
        return os.open(part, _DIR, dir_fd=fd)
    except OSError as exc:
        if exc.errno not in (errno.ELOOP, errno.ENOTDIR):
            raise
        st = lstat_at(fd, part)
        kind = "a symlink" if st is not None and stat.S_ISLNK(st.st_mode) else "not a directory"
        raise UnsafeArchiveError(f"{where}: {'/'.join(parts[: i + 1])} is {kind}; refusing to write "
                                 f"{rel!r} through it") from None


def make_dirs(root_fd: int, rel: str, where: str) -> None:
    """Create the directory ``rel`` (and its parents) below the root, never through a link."""
    with parent_of(root_fd, rel + "/x", create=True, where=where):
        pass


def remove(root_fd: int, rel: str) -> None:
    """Unlink the file or link ``rel`` (a no-op when it is gone or its parent is not a real dir)."""
    with contextlib.suppress(FileNotFoundError, UnsafeArchiveError), \
            parent_of(root_fd, rel, create=False, where="") as (fd, leaf):
        st = lstat_at(fd, leaf)
        if st is not None and not stat.S_ISDIR(st.st_mode):
            os.unlink(leaf, dir_fd=fd)


def walk(root: str | os.PathLike) -> dict[str, tuple]:
    """Every entry below ``root`` without following links: ``{rel: ("f", size) | ("l", target) | ("d",)}``."""
    out: dict[str, tuple] = {}
    root = Path(root)
    for dirpath, dirnames, filenames in os.walk(root):
        base = Path(dirpath)
        for name in dirnames + filenames:
            full = base / name
            rel = full.relative_to(root).as_posix()
            st = os.lstat(full)
            if stat.S_ISLNK(st.st_mode):
                out[rel] = ("l", os.readlink(full))
            elif stat.S_ISDIR(st.st_mode):
                out[rel] = ("d",)
            else:
                out[rel] = ("f", st.st_size)
        dirnames[:] = [d for d in dirnames if not os.path.islink(base / d)]
    return out


def resolves_inside(root: Path, rel: str) -> bool:
    """Whether the link ``root/rel``, resolved through the real filesystem, stays below ``root``."""
    real_root = os.path.realpath(root)
    target = os.path.realpath(os.path.join(root, rel))
    return target == real_root or target.startswith(real_root.rstrip("/") + "/")
