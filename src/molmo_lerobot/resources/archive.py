"""``.tar.zst`` archives: deterministic packing, checksums, and extraction that never follows a link
and never writes more than the archive's index says."""

from __future__ import annotations

import errno
import hashlib
import io
import os
import posixpath
import stat
import tarfile
from collections.abc import Iterable, Mapping
from pathlib import Path, PurePosixPath

import zstandard

from molmo_lerobot.fileio import UnsafePathError, atomic_open, make_dirs_at, open_dir, parent_of
from molmo_lerobot.resources.errors import CorruptArchiveError, ResourceError, UnsafeArchiveError
from molmo_lerobot.resources.manifests import link_escapes

CHUNK = 1 << 20
_HEADER_ALLOWANCE = 8 << 10  # tar header, PAX record and padding per member
_END_ALLOWANCE = 64 << 10  # end-of-archive blocks and record padding


def sha256_file(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(CHUNK):
            h.update(block)
    return h.hexdigest()


def tree_entries(root: Path) -> dict[str, list]:
    """Every file and symlink under ``root`` as ``{rel: [size, sha256]}`` or ``{rel: ["->", target]}``.

    Refuses symlinks that leave ``root`` and anything that is not a file, dir or link.
    """
    root = Path(root)
    if not root.is_dir():
        raise ResourceError(f"{root}: not a directory")
    entries: dict[str, list] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames.sort()
        for name in sorted(filenames) + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
            full = os.path.join(dirpath, name)
            rel = Path(full).relative_to(root).as_posix()
            st = os.lstat(full)
            if stat.S_ISLNK(st.st_mode):
                target = os.readlink(full)
                if link_escapes(rel, target):
                    raise ResourceError(f"{full}: symlink to {target!r} points outside {root}")
                entries[rel] = ["->", target]
            elif stat.S_ISREG(st.st_mode):
                entries[rel] = [st.st_size, sha256_file(full)]
            else:
                raise ResourceError(f"{full}: not a regular file, directory or symlink")
        dirnames[:] = [d for d in dirnames if not os.path.islink(os.path.join(dirpath, d))]
    return entries


def pack_archive(root: Path, rel_paths: Iterable[str], out: Path, level: int = 10) -> dict:
    """Write ``rel_paths`` (files/links under ``root``) into ``out``; returns ``{"size", "sha256"}``.

    Member metadata is normalized (owner, mtime, mode) so the same tree packs to the same bytes.
    """
    out = Path(out)
    cctx = zstandard.ZstdCompressor(level=level)
    with (atomic_open(out, "wb") as fh, cctx.stream_writer(fh, closefd=False) as zw,
          tarfile.open(fileobj=zw, mode="w|", format=tarfile.PAX_FORMAT) as tar):
        for rel in rel_paths:
            info = tar.gettarinfo(str(root / rel), arcname=rel)
            info.uid = info.gid = 0
            info.uname = info.gname = ""
            info.mtime = 0
            if info.isreg():
                info.mode = 0o644
                with open(root / rel, "rb") as src:
                    tar.addfile(info, src)
            else:
                info.mode = 0o777
                tar.addfile(info)
    return {"size": out.stat().st_size, "sha256": sha256_file(out)}


def verify_archive(path: Path, name: str, size: int, sha256: str) -> None:
    """Raise :class:`CorruptArchiveError` unless ``path`` has the manifest's size and sha256."""
    actual_size = Path(path).stat().st_size
    if actual_size != size:
        raise CorruptArchiveError(f"archive {name}: size {actual_size} != manifest size {size}; refusing to extract")
    digest = sha256_file(path)
    if digest != sha256:
        raise CorruptArchiveError(
            f"archive {name}: sha256 {digest[:16]}… != manifest {sha256[:16]}…; refusing to extract"
        )


def check_member(member: tarfile.TarInfo, archive: str) -> None:
    """Refuse absolute paths, ``..``, escaping symlinks/hard links, devices and other specials."""
    name = member.name
    where = f"archive {archive}: member {name!r}"
    if not name or PurePosixPath(name).is_absolute() or name.startswith("/"):
        raise UnsafeArchiveError(f"{where} has an absolute path; refusing to extract")
    if ".." in PurePosixPath(name).parts:
        raise UnsafeArchiveError(f"{where} contains '..' (path traversal); refusing to extract")
    if member.ischr() or member.isblk() or member.isfifo():
        raise UnsafeArchiveError(f"{where} is a device or fifo; refusing to extract")
    if member.issym() and link_escapes(name, member.linkname):
        raise UnsafeArchiveError(f"{where} is a symlink to {member.linkname!r} outside the archive; "
                                 "refusing to extract")
    if member.islnk():
        target = posixpath.normpath(member.linkname)
        if PurePosixPath(target).is_absolute() or target == ".." or target.startswith("../"):
            raise UnsafeArchiveError(f"{where} is a hard link to {member.linkname!r} outside the archive; "
                                     "refusing to extract")
    if not (member.isreg() or member.isdir() or member.issym() or member.islnk()):
        raise UnsafeArchiveError(f"{where} has an unsupported type; refusing to extract")


def extract_limit(entries: Mapping[str, list]) -> int:
    """Most decompressed tar bytes an archive holding ``entries`` may take: data, headers, padding."""
    data = sum(-(-e[0] // 512) * 512 for e in entries.values() if isinstance(e[0], int))
    return data + _HEADER_ALLOWANCE * (len(entries) + len(_ancestors(entries))) + _END_ALLOWANCE


def _ancestors(paths: Iterable[str]) -> set[str]:
    out: set[str] = set()
    for p in paths:
        parent = posixpath.dirname(p)
        while parent and parent not in out:
            out.add(parent)
            parent = posixpath.dirname(parent)
    return out


class _Capped(io.RawIOBase):
    """A decompressed stream that refuses to yield more than ``limit`` bytes."""

    def __init__(self, raw, limit: int | None, name: str) -> None:
        self.raw, self.limit, self.name, self.count = raw, limit, name, 0

    def readable(self) -> bool:
        return True

    def read(self, n: int = -1) -> bytes:
        data = self.raw.read(n)
        self.count += len(data)
        if self.limit is not None and self.count > self.limit:
            raise UnsafeArchiveError(f"archive {self.name}: decompresses past its limit of {self.limit} bytes "
                                     "(from its index); refusing to extract")
        return data


def safe_extract(archive_path: Path, dest: Path, name: str, expected: Mapping[str, list] | None = None,
                 limit: int | None = None, *, root: Path | None = None) -> list[str]:
    """Stream-extract ``archive_path`` into the new directory ``dest``; returns the member paths.

    Nothing is written through a link: ``dest`` is made below ``root`` (default: its parent) and
    every path is walked with ``O_NOFOLLOW`` from it (:mod:`molmo_lerobot.fileio`).
    With ``expected`` (the index's ``{path: entry}``) a member that is not indexed, repeated,
    of another kind, or larger than its indexed size is refused before a byte of it is
    written, so an archive never writes more than its index says; ``limit`` (default:
    :func:`extract_limit` of ``expected``) caps the decompressed stream itself.
    """
    dest = Path(dest)
    if dest.exists() or dest.is_symlink():
        raise FileExistsError(errno.EEXIST, f"{dest} already exists; extraction needs a new directory")
    if expected is not None and limit is None:
        limit = extract_limit(expected)
    dirs = _ancestors(expected) if expected is not None else set()
    seen: dict[str, str] = {}
    written = 0
    dctx = zstandard.ZstdDecompressor()
    try:
        with open(archive_path, "rb") as fh, dctx.stream_reader(fh) as zr, \
                open_dir(dest, root=root or dest.parent) as dfd, \
                tarfile.open(fileobj=_Capped(zr, limit, name), mode="r|") as tar:
            for member in tar:
                check_member(member, name)
                rel = posixpath.normpath(member.name)
                if rel == ".":
                    continue
                where = f"archive {name}: member {rel!r}"
                if rel in seen:
                    raise UnsafeArchiveError(f"{where} appears twice; refusing to extract")
                size = _check_expected(member, rel, expected, dirs, seen, where)
                if limit is not None and written + size > limit:
                    raise UnsafeArchiveError(f"{where} would take the archive past its limit of {limit} bytes "
                                             "(from its index); refusing to extract")
                written += size
                _write_member(tar, member, rel, dfd, seen, where)
                seen[rel] = "d" if member.isdir() else "l" if member.issym() else "f"
    except UnsafePathError as exc:
        raise UnsafeArchiveError(str(exc)) from None
    except (tarfile.TarError, zstandard.ZstdError, EOFError) as exc:
        raise CorruptArchiveError(f"archive {name}: cannot be read ({type(exc).__name__}: {exc})") from None
    if expected is not None:
        missing = sorted(set(expected) - set(seen))
        if missing:
            raise CorruptArchiveError(f"archive {name}: contents differ from the index (missing {missing[:3]})")
    return [rel for rel in seen]


def _check_expected(member: tarfile.TarInfo, rel: str, expected: Mapping[str, list] | None, dirs: set[str],
                    seen: dict[str, str], where: str) -> int:
    """Bytes the member will write, after checking it against its index entry."""
    size = member.size if member.isreg() else 0
    if member.islnk():
        target = posixpath.normpath(member.linkname)
        if seen.get(target) != "f":
            raise UnsafeArchiveError(f"{where} is a hard link to {member.linkname!r}, which is not an earlier "
                                     "regular file of the archive; refusing to extract")
    if expected is None:
        return size
    want = expected.get(rel)
    if want is None:
        if member.isdir() and rel in dirs:
            return 0
        raise CorruptArchiveError(f"{where} is not in the index; archive contents differ from the index "
                                  "(unexpected member)")
    kind, value = want[0], want[1]
    if kind == "->":
        if not member.issym() or member.linkname != value:
            raise CorruptArchiveError(f"{where} is not the link to {value!r} the index names")
    elif kind is not None:
        if not (member.isreg() or member.islnk()):
            raise CorruptArchiveError(f"{where} is not a regular file as the index says")
        if member.islnk():
            return kind  # a copy of an earlier member: its indexed size
        if member.size != kind:
            raise UnsafeArchiveError(f"{where} has size {member.size}, but its indexed size is {kind}; "
                                     "refusing to extract")
    return size


def _write_member(tar: tarfile.TarFile, member: tarfile.TarInfo, rel: str, root: int, seen: dict[str, str],
                  where: str) -> None:
    if member.isdir():
        make_dirs_at(root, rel, where)
        return
    with parent_of(root, rel, create=True, where=where) as (fd, leaf):
        if member.issym():
            os.symlink(member.linkname, leaf, dir_fd=fd)
            return
        out = os.open(leaf, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644, dir_fd=fd)
        with open(out, "wb") as dst:
            if member.islnk():
                with parent_of(root, posixpath.normpath(member.linkname), create=False, where=where) as (sfd, sleaf):
                    src = os.open(sleaf, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC, dir_fd=sfd)
                    with open(src, "rb") as fh:
                        _copy(fh, dst, None)
            else:
                _copy(tar.extractfile(member), dst, member.size)


def _copy(src, dst, size: int | None) -> None:
    left = size
    while left is None or left > 0:
        block = src.read(CHUNK if left is None else min(CHUNK, left))
        if not block:
            break
        dst.write(block)
        if left is not None:
            left -= len(block)
