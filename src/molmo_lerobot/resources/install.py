"""Installing a version: download, check and extract its archives into the version dir, and link the
version into the install dir.

Nothing is ever written through a link below the cache or install dir (either may itself be a
link): every write, new directory, rename and removal walks its path from that root with
``O_NOFOLLOW`` (:mod:`molmo_lerobot.fileio`), and each link a version brings is resolved through the
real tree and must stay inside the version. The callers (the manager) hold the locks.
"""

from __future__ import annotations

import contextlib
import json
import os
import stat
import sys
import threading
import uuid
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from molmo_lerobot import fileio
from molmo_lerobot.fileio import UnsafePathError, atomic_write
from molmo_lerobot.resources.archive import safe_extract
from molmo_lerobot.resources.errors import CorruptArchiveError, ResourceError, UnsafeArchiveError
from molmo_lerobot.resources.formats import LAYOUTS
from molmo_lerobot.resources.index import PathIndex
from molmo_lerobot.resources.layout import Layout
from molmo_lerobot.resources.manifests import read_json
from molmo_lerobot.resources.remotes import Remote
from molmo_lerobot.resources.spec import VersionPlace


@dataclass
class Extraction:
    """One version's archives going into its version dir: what to fetch them from and check them against."""

    place: VersionPlace
    manifest: dict
    index: PathIndex
    layout: Layout
    remote: Remote
    #: one archive moves into a version dir at a time (the manager's, shared by its threads)
    place_lock: threading.Lock

    def run(self, archives: list[str], *, workers: int, progress: bool | None) -> None:
        """Download, verify and extract ``archives`` on a thread pool, with one retry pass."""
        spec = self.place.spec
        from tqdm.auto import tqdm

        entries = self.manifest["archives"]
        show = progress if progress is not None else sys.stderr.isatty()
        bar = tqdm(total=sum(entries[a]["size"] for a in archives), unit="B", unit_scale=True,
                   desc=f"install {spec}", disable=not show, leave=False)
        bar_lock = threading.Lock()

        def one(name: str) -> None:
            self.archive(name, entries[name])
            with bar_lock:
                bar.update(entries[name]["size"])

        pending = list(archives)
        try:
            for attempt in range(2):
                errors: dict[str, BaseException] = {}
                with ThreadPoolExecutor(min(workers, len(pending))) as pool:
                    for name, fut in [(n, pool.submit(one, n)) for n in pending]:
                        try:
                            fut.result()
                        except Exception as exc:  # collected, retried once, then raised
                            errors[name] = exc
                fatal = [e for e in errors.values()
                         if isinstance(e, (UnsafeArchiveError, UnsafePathError)) or not getattr(e, "retryable", True)]
                if not errors or fatal or attempt == 1:
                    break
                pending = list(errors)
        finally:
            bar.close()
        if errors:
            first = (fatal or list(errors.values()))[0]
            if isinstance(first, ResourceError):
                raise first if str(first).startswith(f"{spec}:") else type(first)(f"{spec}: {first}") from None
            raise ResourceError(f"{spec}: installing {len(errors)} archive(s) failed: {first}") from first

    def archive(self, name: str, entry: dict) -> None:
        """Download, verify, extract (never past the index) and move one archive into place.

        Only the download and its checks may be retried: once an archive with the manifest's
        checksum fails to extract or place, the same bytes would fail again.
        """
        place, root = self.place, self.place.cache_dir
        files = self.index.files(name)
        tmp = fileio.make_dirs(place.meta_dir / "tmp", root=root)
        token = uuid.uuid4().hex
        part, xdir = tmp / f"{token}.part", tmp / f"x-{token}"
        try:
            inflated = self.remote.fetch_archive(place.spec.rel, name, part, self.layout.format)
            limit = self.layout.check_download(part, name, entry, files, inflated)
            try:
                safe_extract(part, xdir, name, files, limit, root=root)
                self.place_archive(name, xdir, files)
            except ResourceError as exc:
                exc.retryable = False
                raise
            self.layout.mark_done(name, entry)
        finally:
            fileio.remove(part, root=root)
            fileio.rmtree(xdir, root=root, onexc=force_remove)

    def place_archive(self, name: str, xdir: Path, files: dict[str, list]) -> None:
        """Move an extracted archive into the version dir without following any link, then check
        every link of the version against the real tree; on a problem, take the archive out again."""
        vdir, root = self.place.version_dir, self.place.cache_dir
        where = f"archive {name}"
        with self.place_lock, fileio.open_dir(xdir, root=root, create=False) as xroot, \
                fileio.open_dir(vdir, root=root) as vroot:
            placed: list[str] = []
            try:
                for rel in sorted(files):
                    with fileio.parent_of(xroot, rel, create=False, where=where) as (xfd, leaf), \
                            fileio.parent_of(vroot, rel, create=True, where=where) as (vfd, _):
                        st = fileio.lstat_at(xfd, leaf)
                        if st is None:
                            raise CorruptArchiveError(f"{where}: {rel} was not extracted")
                        if stat.S_ISDIR(st.st_mode):
                            fileio.make_dirs_at(vroot, rel, where)
                            continue
                        if stat.S_ISREG(st.st_mode):
                            os.chmod(leaf, 0o444, dir_fd=xfd)
                        old = fileio.lstat_at(vfd, leaf)
                        if old is not None and stat.S_ISDIR(old.st_mode):
                            raise ResourceError(f"{where}: {rel} would replace a directory in {vdir}")
                        os.replace(leaf, leaf, src_dir_fd=xfd, dst_dir_fd=vfd)
                        placed.append(rel)
                check_links(self.place, [r for r in placed if files[r][0] in ("->", None)], where)
            except BaseException as exc:
                for rel in placed:
                    fileio.remove_at(vroot, rel)
                if isinstance(exc, UnsafePathError):
                    raise UnsafeArchiveError(str(exc)) from None
                raise


def check_links(place: VersionPlace, new: list[str], where: str) -> None:
    """Every link of the version must resolve, through the real tree, inside the version dir.

    A new link can change where an older one leads (``a -> .`` makes ``b -> a/..`` escape),
    so all links placed so far (listed in ``links.json``) are rechecked whenever an archive brings links.
    """
    vdir = place.version_dir
    new = [r for r in new if os.path.islink(vdir / r)]
    if not new:
        return
    path = place.meta_dir / "links.json"
    known = read_json(path) if path.is_file() else []
    known = known if isinstance(known, list) else []
    links = sorted({r for r in known if isinstance(r, str) and os.path.islink(vdir / r)} | set(new))
    bad = [r for r in links if not fileio.resolves_inside(vdir, r)]
    if bad:
        raise UnsafeArchiveError(f"{where}: link {bad[0]!r} -> {os.readlink(vdir / bad[0])!r} resolves to "
                                 f"{os.path.realpath(vdir / bad[0])}, outside {vdir}, through the links of "
                                 "this version; refusing to install")
    atomic_write(path, json.dumps(links), root=place.cache_dir)


def clean_tmp(place: VersionPlace) -> None:
    """Remove what a killed install left behind (the caller holds the version lock)."""
    fileio.rmtree(place.meta_dir / "tmp", root=place.cache_dir, onexc=force_remove)


def link_version(place: VersionPlace, layout: Layout, index: PathIndex, current: str | None) -> Path:
    """Point ``<install>/<data_type>/<source>`` at the version: one link (manifest ``link`` ``dir``), or a
    tree of per-file links to the files of its done archives (``file``; ``current``: the version linked
    now, whose tree is added to when it is this one). The caller holds the install dir's locks and
    records the link."""
    link, target, install = place.link_path, place.version_dir, place.install_dir
    assert install is not None
    fileio.make_dirs(link.parent, root=install)
    token = uuid.uuid4().hex
    if layout.manifest["link"] == "dir":
        if not (link.is_symlink() and os.readlink(link) == str(target)):
            fileio.make_dirs(target, root=place.cache_dir)
            tmp = link.parent / f".{link.name}.{token}.link"
            fileio.symlink(target, tmp, root=install)
            if link.is_dir() and not link.is_symlink():
                remove_link_tree(link, install)
            fileio.replace(tmp, link, root=install)
        return link
    done = sorted(layout.done() & set(layout.manifest["archives"]))
    files = [rel for a in done for rel in index.files(a)] + layout.link_files()
    if current == place.spec.version and link.is_dir() and not link.is_symlink():
        make_links(link, target, files, install)  # same version: add what on-demand installs brought
        layout.flag_links(link, done)
        return link
    new = link.parent / f".{link.name}.{token}.new"
    make_links(new, target, files, install)
    layout.flag_links(new, done)
    if link.is_symlink():
        fileio.remove(link, root=install)
    elif link.exists():
        old = link.parent / f".{link.name}.{token}.old"
        fileio.replace(link, old, root=install)
        fileio.replace(new, link, root=install)
        remove_link_tree(old, install)
    if not link.exists():
        fileio.replace(new, link, root=install)
    return link


def make_links(root: Path, target: Path, files: Iterable[str], install: Path) -> None:
    """Per-file links ``root/rel -> target/rel``, made without following any link below ``install``."""
    with fileio.open_dir(root, root=install) as rfd:
        for rel in files:
            with fileio.parent_of(rfd, rel, create=True, where=f"install dir {root}") as (fd, leaf):
                if fileio.lstat_at(fd, leaf) is None:
                    os.symlink(target / rel, leaf, dir_fd=fd)


def remove_link_tree(path: Path, install: Path) -> None:
    """Delete a tree of links made by :func:`make_links` (and a layout's flags), refusing one that holds real files."""
    for dirpath, _dirnames, filenames in os.walk(path):
        for name in filenames:
            if dirpath == str(path) and any(layout.own_link_file(name) for layout in LAYOUTS.values()):
                continue
            if not os.path.islink(os.path.join(dirpath, name)):
                raise ResourceError(f"{path} holds real files ({name}); refusing to replace it with links")
    fileio.rmtree(path, root=install)


def force_remove(func, path, _exc: BaseException) -> None:
    """``rmtree`` error handler: make read-only entries writable and retry."""
    with contextlib.suppress(OSError):
        os.chmod(os.path.dirname(path), 0o755)
        os.chmod(path, 0o755)
        func(path)
