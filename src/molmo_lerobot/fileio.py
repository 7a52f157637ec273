"""The one write path: atomic, durable writes that never follow a symbolic link below a root.

Every write under a run directory, a resource cache or an install dir goes through here.
A path is written relative to a *root* (the run's ``output_dir``, the cache dir, ...): the
root itself may be a link (people relocate caches and output dirs), but every component
below it is walked one at a time from a directory file descriptor opened with
``O_NOFOLLOW``, so a link planted inside the root — dangling or not — can never redirect a
write, a new directory, a rename or a removal outside it. Such a link is refused with
:class:`UnsafePathError`, an :class:`OSError` whose one-line message names the path.
Without ``root`` the path's parent directory is the root.

Atomic writes go to a uniquely named temporary file in the checked directory, which is
flushed and fsynced, renamed over the target (a link there is replaced, never followed),
and then the directory is fsynced so that the rename itself survives a crash. On any error
the temporary file is removed and the target is untouched. Files get the usual
permissions (``0o666`` less the umask).

Libraries that write a tree themselves (LeRobot's dataset writer, LMDB) get a directory
made by :func:`make_dirs`: link-free from the root down when it is handed over.

Reads that must not go through a link either (the dataset store's) use :func:`read_bytes`, which
also never opens a FIFO or device, and :func:`walk`, which lists a tree without following one.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import stat
import uuid
from collections.abc import Iterator
from pathlib import Path, PurePosixPath
from typing import IO, Any, NoReturn

from molmo_lerobot.errors import INFRASTRUCTURE, MolmoError

_DIR = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC
_NEW = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC


class UnsafePathError(MolmoError, OSError):
    """A write would go through a symbolic link (or a non-directory) below its root. The machine's state, not
    an episode's doing: an episode it ends is an infrastructure failure (rerun by ``resume=true`` once fixed)."""

    kind = INFRASTRUCTURE

    def __str__(self) -> str:  # the one-line message, without "[Errno 40]"
        return self.strerror or super().__str__()


# -- descriptor level: a root fd and paths relative to it -------------------------------------
@contextlib.contextmanager
def open_root(path: str | os.PathLike, *, create: bool = True) -> Iterator[int]:
    """A directory fd on the root ``path`` (which may be a link; made with its parents when missing)."""
    if create:
        os.makedirs(path, exist_ok=True)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except NotADirectoryError:
        raise UnsafePathError(errno.ENOTDIR, f"{path} is not a directory; refusing to write into it") from None
    try:
        yield fd
    finally:
        os.close(fd)


def lstat_at(dir_fd: int, name: str) -> os.stat_result | None:
    """``lstat`` of ``name`` in the directory ``dir_fd``; None when it does not exist."""
    try:
        return os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
    except FileNotFoundError:
        return None


def _walk(root_fd: int, parts: tuple[str, ...], create: bool, rel: str, where: str) -> int:
    """A new fd on the directory reached from ``root_fd`` through ``parts``, never through a link."""
    fd = os.dup(root_fd)
    try:
        for i, part in enumerate(parts):
            try:
                nfd = os.open(part, _DIR, dir_fd=fd)
            except FileNotFoundError:
                if not create:
                    raise
                with contextlib.suppress(FileExistsError):
                    os.mkdir(part, 0o777, dir_fd=fd)
                nfd = _open_dir(fd, part, parts, i, rel, where)
            except OSError as exc:
                if exc.errno not in (errno.ELOOP, errno.ENOTDIR):
                    raise
                nfd = _open_dir(fd, part, parts, i, rel, where)
            os.close(fd)
            fd = nfd
    except BaseException:
        os.close(fd)
        raise
    return fd


def _parts(rel: str, where: str) -> tuple[str, ...]:
    parts = PurePosixPath(rel).parts
    if not parts or any(p in ("..", "/") for p in parts):
        raise UnsafePathError(errno.EINVAL, f"{where}: {rel!r} is not a path below the root")
    return parts


@contextlib.contextmanager
def parent_of(root_fd: int, rel: str, *, create: bool, where: str) -> Iterator[tuple[int, str]]:
    """``(fd of rel's parent dir, rel's last component)``; missing dirs are made when ``create``.

    Raises :class:`UnsafePathError` ("``where``: ``a/b`` is a symlink; refusing to write ...")
    when a component is a link or not a directory; :class:`FileNotFoundError` when one is
    missing and not ``create``.
    """
    parts = _parts(rel, where)
    fd = _walk(root_fd, parts[:-1], create, rel, where)
    try:
        yield fd, parts[-1]
    finally:
        os.close(fd)


@contextlib.contextmanager
def dir_at(root_fd: int, rel: str, *, create: bool, where: str) -> Iterator[int]:
    """An fd on the directory ``rel`` below the root (made with its parents when ``create``), as :func:`parent_of`."""
    fd = _walk(root_fd, _parts(rel, where), create, rel, where)
    try:
        yield fd
    finally:
        os.close(fd)


def _open_dir(fd: int, part: str, parts: tuple, i: int, rel: str, where: str) -> int:
    try:
        return os.open(part, _DIR, dir_fd=fd)
    except OSError as exc:
        if exc.errno not in (errno.ELOOP, errno.ENOTDIR):
            raise
        _refuse(fd, part, "/".join(parts[: i + 1]), rel, where)


def _refuse(fd: int, leaf: str, shown: str, rel: str, where: str) -> NoReturn:
    st = lstat_at(fd, leaf)
    link = st is not None and stat.S_ISLNK(st.st_mode)
    what = "" if shown == rel else f"{rel!r} "
    raise UnsafePathError(errno.ELOOP if link else errno.ENOTDIR, f"{where}: {shown} is "
                          f"{'a symlink' if link else 'not a directory'}; refusing to write {what}through it")


def make_dirs_at(root_fd: int, rel: str, where: str) -> None:
    """Create the directory ``rel`` (and its parents) below the root, never through a link."""
    with dir_at(root_fd, rel, create=True, where=where):
        pass


def remove_at(root_fd: int, rel: str) -> None:
    """Unlink the file or link ``rel`` (a no-op when it is gone or its parent is not a real dir)."""
    with contextlib.suppress(FileNotFoundError, UnsafePathError), \
            parent_of(root_fd, rel, create=False, where="") as (fd, leaf):
        st = lstat_at(fd, leaf)
        if st is not None and not stat.S_ISDIR(st.st_mode):
            os.unlink(leaf, dir_fd=fd)


# -- path level: ``path`` below ``root`` ---------------------------------------------------------
def _split(path: str | os.PathLike, root: str | os.PathLike | None) -> tuple[Path, str]:
    """``(root, path relative to it)``, both lexically normalized; ``path`` must lie below ``root``."""
    path = Path(os.path.abspath(path))
    base = path.parent if root is None else Path(os.path.abspath(root))
    try:
        rel = path.relative_to(base)
    except ValueError:
        raise UnsafePathError(errno.EINVAL, f"{path} is not below {base}; refusing to write it") from None
    if not rel.parts:
        raise UnsafePathError(errno.EINVAL, f"{path} is the root itself, not a path below it")
    return base, rel.as_posix()


@contextlib.contextmanager
def _parent(path: str | os.PathLike, root: str | os.PathLike | None, create: bool = True,
            parents: bool = False) -> Iterator[tuple[int, str]]:
    """``(parent dir fd, leaf)`` of ``path``; without ``root`` its parent is made only when ``parents``."""
    base, rel = _split(path, root)
    with open_root(base, create=create and (root is not None or parents)) as rfd, \
            parent_of(rfd, rel, create=create, where=str(base)) as got:
        yield got


@contextlib.contextmanager
def open_dir(path: str | os.PathLike, *, root: str | os.PathLike, create: bool = True) -> Iterator[int]:
    """A directory fd on ``path`` below ``root``, walked (and made when ``create``) without following links."""
    base, rel = _split(path, root)
    with open_root(base, create=create) as rfd, dir_at(rfd, rel, create=create, where=str(base)) as fd:
        yield fd


def make_dirs(path: str | os.PathLike, *, root: str | os.PathLike) -> Path:
    """Create the directory ``path`` below ``root`` (the root too when missing), refusing any link below
    the root, ``path`` itself included; returns ``path``."""
    with open_dir(path, root=root):
        pass
    return Path(path)


def open_fd(path: str | os.PathLike, flags: int, mode: int = 0o666, *, root: str | os.PathLike | None = None) -> int:
    """``os.open(path, flags | O_NOFOLLOW)`` after a link-free walk from ``root`` (missing dirs are made):
    for files written in place (appended logs). A link as the file itself is refused too."""
    with _parent(path, root, parents=True) as (fd, leaf):
        try:
            return os.open(leaf, flags | os.O_NOFOLLOW | os.O_CLOEXEC, mode, dir_fd=fd)
        except OSError as exc:
            if exc.errno != errno.ELOOP:
                raise
            base, rel = _split(path, root)
            _refuse(fd, leaf, rel, rel, str(base))


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", *, root: str | os.PathLike | None = None,
                parents: bool = False, durable: bool = True, **kwargs: Any) -> Iterator[IO[Any]]:
    """``with atomic_open(path, "wb", root=out) as f: ...``: ``path`` gets what was written, once the block
    succeeds. Missing directories from ``root`` down are made (none may be a link); without ``root``,
    ``parents=True`` makes the missing parents. ``durable=False`` skips the fsyncs (files nobody
    needs after a crash, such as progress notes)."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: mode must be 'w' or 'wb', got {mode!r}")
    with _parent(path, root, parents=parents) as (dfd, leaf):
        tmp = f".{leaf}.{uuid.uuid4().hex}.tmp"
        fd = os.open(tmp, _NEW, 0o666, dir_fd=dfd)
        try:
            with open(fd, mode, **kwargs) as f:
                yield f
                f.flush()
                if durable:
                    os.fsync(f.fileno())
            os.replace(tmp, leaf, src_dir_fd=dfd, dst_dir_fd=dfd)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp, dir_fd=dfd)
            raise
        if durable:
            os.fsync(dfd)


def atomic_write(path: str | os.PathLike, data: str | bytes, *, root: str | os.PathLike | None = None,
                 parents: bool = False, durable: bool = True, encoding: str = "utf-8") -> Path:
    """Replace ``path``'s content with ``data`` atomically and durably; return ``path``.

    With ``root``, missing directories from it down are made (refusing links); without it,
    ``parents=True`` creates the missing parent directories first.
    """
    if isinstance(data, bytes):
        with atomic_open(path, "wb", root=root, parents=parents, durable=durable) as f:
            f.write(data)
    else:
        with atomic_open(path, "w", root=root, parents=parents, durable=durable, encoding=encoding) as f:
            f.write(data)
    return Path(path)


def replace(src: str | os.PathLike, dst: str | os.PathLike, *, root: str | os.PathLike) -> None:
    """``os.replace(src, dst)`` with both parents walked from ``root`` without following links."""
    with _parent(src, root, create=False) as (sfd, sleaf), _parent(dst, root) as (dfd, dleaf):
        os.replace(sleaf, dleaf, src_dir_fd=sfd, dst_dir_fd=dfd)


def symlink(target: str | os.PathLike, path: str | os.PathLike, *, root: str | os.PathLike) -> None:
    """Create the link ``path -> target`` (missing directories below ``root`` are made, none a link)."""
    with _parent(path, root) as (fd, leaf):
        os.symlink(target, leaf, dir_fd=fd)


def remove(path: str | os.PathLike, *, root: str | os.PathLike | None = None) -> None:
    """Unlink the file or link ``path`` below ``root``; nothing happens when it is missing, and nothing
    is removed through a link (a linked parent leaves the outside file alone)."""
    base, rel = _split(path, root)
    with contextlib.suppress(FileNotFoundError), open_root(base, create=False) as rfd:
        remove_at(rfd, rel)


def rmtree(path: str | os.PathLike, *, root: str | os.PathLike, ignore_errors: bool = False,
           onexc: Any = None) -> None:
    """Remove the tree ``path`` below ``root``: a link as ``path`` is unlinked, a link on the way there
    refused, and ``shutil.rmtree`` never follows one inside the tree. A missing ``path`` is no error;
    ``onexc`` is ``shutil.rmtree``'s (it gets full paths)."""
    try:
        with _parent(path, root, create=False) as (fd, leaf):
            st = lstat_at(fd, leaf)
            if st is None:
                return
            if stat.S_ISDIR(st.st_mode):  # by path (checked above) so that ``onexc`` gets real paths
                shutil.rmtree(path, ignore_errors=ignore_errors, onexc=onexc)
            else:
                os.unlink(leaf, dir_fd=fd)
    except FileNotFoundError:
        return
    except OSError:
        if not ignore_errors:
            raise


def refuse_link(path: str | os.PathLike) -> None:
    """Raise :class:`UnsafePathError` when ``path`` itself is a symbolic link (before reading it as run data)."""
    if os.path.islink(path):
        raise UnsafePathError(errno.ELOOP, f"{path} is a symlink; refusing to use it as part of the run")


# -- reading without following links ------------------------------------------------------------
def read_bytes(path: str | os.PathLike, *, root: str | os.PathLike) -> bytes:
    """The content of the regular file ``path`` below ``root``, reached without following a link: a link
    on the way or as ``path``, a FIFO or another non-regular file is refused (:class:`UnsafePathError`)
    without being opened, so that a planted FIFO never hangs the reader."""
    base, rel = _split(path, root)
    parts = _parts(rel, str(base))
    with open_root(base, create=False) as rfd:
        fd = os.dup(rfd)
        try:
            for i, part in enumerate(parts):
                last = i == len(parts) - 1
                st = lstat_at(fd, part)
                if st is None:
                    raise FileNotFoundError(errno.ENOENT, "No such file or directory", str(base / rel))
                if not (stat.S_ISREG if last else stat.S_ISDIR)(st.st_mode):
                    _refuse_read(base / "/".join(parts[: i + 1]), st, leaf=last)
                flags = (os.O_RDONLY | os.O_NONBLOCK) if last else _DIR
                nfd = os.open(part, flags | os.O_NOFOLLOW | os.O_CLOEXEC, dir_fd=fd)
                os.close(fd)
                fd = nfd
            st = os.fstat(fd)  # what was opened, should it have been swapped since the lstat
            if not stat.S_ISREG(st.st_mode):
                _refuse_read(base / rel, st, leaf=True)
            with open(fd, "rb") as f:
                fd = -1  # the file object owns it
                return f.read()
        finally:
            if fd >= 0:
                os.close(fd)


def _refuse_read(path: Path, st: os.stat_result, *, leaf: bool) -> NoReturn:
    link = stat.S_ISLNK(st.st_mode)
    what = "a symlink" if link else "not a directory" if not leaf else "a directory" if stat.S_ISDIR(st.st_mode) \
        else "not a regular file"
    raise UnsafePathError(errno.ELOOP if link else errno.EINVAL, f"{path} is {what}; refusing to read through it")


def walk(root: str | os.PathLike) -> dict[str, tuple]:
    """Every entry below ``root`` without following links:
    ``{rel: ("f", size) | ("l", target) | ("d",) | ("o",)}`` (``o``: a FIFO, socket or device)."""
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
            elif stat.S_ISREG(st.st_mode):
                out[rel] = ("f", st.st_size)
            else:
                out[rel] = ("o",)
        dirnames[:] = [d for d in dirnames if not os.path.islink(base / d)]
    return out


def resolves_inside(root: Path, rel: str) -> bool:
    """Whether the link ``root/rel``, resolved through the real filesystem, stays below ``root``."""
    real_root = os.path.realpath(root)
    target = os.path.realpath(os.path.join(root, rel))
    return target == real_root or target.startswith(real_root.rstrip("/") + "/")
