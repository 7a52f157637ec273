"""``.tar.zst`` archives: deterministic packing, checksums, and extraction that refuses escapes."""

from __future__ import annotations

import hashlib
import os
import posixpath
import stat
import tarfile
from collections.abc import Iterable
from pathlib import Path, PurePosixPath

import zstandard

from molmo_lerobot.resources.errors import CorruptArchiveError, ResourceError, UnsafeArchiveError

CHUNK = 1 << 20


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
                if _link_escapes(rel, target):
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
    part = out.with_name(out.name + ".part")
    cctx = zstandard.ZstdCompressor(level=level)
    with open(part, "wb") as fh, cctx.stream_writer(fh, closefd=False) as zw:
        with tarfile.open(fileobj=zw, mode="w|", format=tarfile.PAX_FORMAT) as tar:
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
    os.replace(part, out)
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


def _link_escapes(member: str, target: str) -> bool:
    if not target or PurePosixPath(target).is_absolute():
        return True
    resolved = posixpath.normpath(posixpath.join(posixpath.dirname(member), target))
    return resolved == ".." or resolved.startswith("../") or resolved.startswith("/")


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
    if member.issym() and _link_escapes(name, member.linkname):
        raise UnsafeArchiveError(f"{where} is a symlink to {member.linkname!r} outside the archive; refusing to extract")
    if member.islnk():
        target = posixpath.normpath(member.linkname)
        if PurePosixPath(target).is_absolute() or target == ".." or target.startswith("../"):
            raise UnsafeArchiveError(f"{where} is a hard link to {member.linkname!r} outside the archive; refusing to extract")
    if not (member.isreg() or member.isdir() or member.issym() or member.islnk()):
        raise UnsafeArchiveError(f"{where} has an unsupported type; refusing to extract")


def safe_extract(archive_path: Path, dest: Path, name: str) -> list[str]:
    """Stream-extract ``archive_path`` into the (new, empty) directory ``dest``; returns member names.

    Every member is checked before it is written, and Python's ``data`` extraction filter
    re-checks the real paths, so nothing is ever written outside ``dest``.
    """
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=False)
    names: list[str] = []
    dctx = zstandard.ZstdDecompressor()
    try:
        with open(archive_path, "rb") as fh, dctx.stream_reader(fh) as zr, tarfile.open(fileobj=zr, mode="r|") as tar:
            for member in tar:
                check_member(member, name)
                tar.extract(member, dest, filter="data", set_attrs=False)
                names.append(member.name)
    except tarfile.FilterError as exc:
        raise UnsafeArchiveError(f"archive {name}: {exc}; refusing to extract") from None
    except (tarfile.TarError, zstandard.ZstdError, EOFError) as exc:
        raise CorruptArchiveError(f"archive {name}: cannot be read ({type(exc).__name__}: {exc})") from None
    return names
