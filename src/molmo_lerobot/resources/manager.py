"""The resource manager: a versioned read-only cache and a version-free install dir of links.

Cache ``<cache>/<data_type>/<source>/<version>/`` holds exactly the packed tree, files
read-only; bookkeeping lives beside it in ``<cache>/.molmo/`` (manifests, LMDB index,
per-archive completion flags, locks, temporary extraction dirs). The install dir holds
``<install>/<data_type>/<source>`` — one link to the version dir (``link="dir"``) or a tree
of per-file links (``link="file"``, so relative MJCF paths resolve). Upgrades re-point links.
What a version's format keeps beyond that (its metadata source, done marks, archive checks, the
locks and records of another tool sharing the cache) is its :class:`~.layout.Layout`, chosen by
the manifest's ``format`` from :data:`LAYOUTS`.

Nothing is ever written through a link below the cache or install dir (either may itself be a
link): every write, new directory, rename and removal walks its path from that root with
``O_NOFOLLOW`` (:mod:`molmo_lerobot.fileio`), and each link a version brings is resolved
through the real tree and must stay inside the version.
"""

from __future__ import annotations

import contextlib
import gzip
import json
import os
import re
import socket
import stat
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Literal

from filelock import FileLock, Timeout

from molmo_lerobot import fileio
from molmo_lerobot.fileio import UnsafePathError, atomic_open, atomic_write
from molmo_lerobot.resources.archive import pack_archive, safe_extract, sha256_file, tree_entries
from molmo_lerobot.resources.errors import CorruptArchiveError, ResourceError, StaleLockError, UnsafeArchiveError
from molmo_lerobot.resources.index import PathIndex, uid_of
from molmo_lerobot.resources.layout import Layout, OwnLayout
from molmo_lerobot.resources.manifests import check_index, check_local, parse_manifest, read_json
from molmo_lerobot.resources.molmospaces import MolmoSpacesLayout
from molmo_lerobot.resources.remotes import Remote, open_remote

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
LINK_MODES = ("dir", "file")
META = ".molmo"
#: Every layout, in the order a remote is probed for a version's metadata; a manifest's ``format``
#: picks one (ours have an integer format).
LAYOUTS: tuple[type[Layout], ...] = (OwnLayout, MolmoSpacesLayout)


@dataclass(frozen=True)
class ResourceSpec:
    """One resource version, written ``data_type/source@version``."""

    data_type: str
    source: str
    version: str

    def __post_init__(self) -> None:
        for field, value in (("data_type", self.data_type), ("source", self.source), ("version", self.version)):
            if not _NAME.match(value or ""):
                raise ResourceError(f"invalid {field} {value!r}: use letters, digits, '.', '_' or '-'")

    @classmethod
    def parse(cls, text: str | ResourceSpec) -> ResourceSpec:
        if isinstance(text, ResourceSpec):
            return text
        m = re.fullmatch(r"([^/@]+)/([^/@]+)@([^/@]+)", text.strip())
        if not m:
            raise ResourceError(f"invalid resource {text!r}: expected DATA_TYPE/SOURCE@VERSION")
        return cls(*m.groups())

    @property
    def rel(self) -> str:
        return f"{self.data_type}/{self.source}/{self.version}"

    def __str__(self) -> str:
        return f"{self.data_type}/{self.source}@{self.version}"


@dataclass
class InstallResult:
    spec: ResourceSpec
    path: Path  # version-free install path, or the cache version dir when there is no install dir
    extracted: int  # archives this call downloaded and extracted
    present: int  # archives that were already complete in the cache
    on_demand: bool


PostSetup = Callable[["ResourceManager", ResourceSpec, Path], None]


class ResourceManager:
    """Installs resource versions from a remote into a cache and links them into an install dir.

    Versions in MolmoSpaces' layout (:class:`~molmo_lerobot.resources.molmospaces.MolmoSpacesLayout`)
    keep molmospaces-resources' flags, local manifests, links and locks, so either tool can use
    what the other installed.

    ``use_lock=False`` is for workers reading a cache that a leader has filled: nothing is
    locked or written, and anything missing is an error instead of an install.
    ``post_setup`` callables run after every install as ``hook(manager, spec, path)``.
    """

    def __init__(self, cache_dir: str | os.PathLike, install_dir: str | os.PathLike | None = None,
                 remote: Remote | str | os.PathLike | None = None, *, use_lock: bool = True, workers: int = 4,
                 progress: bool | None = None, lock_timeout: float = 600.0,
                 post_setup: Iterable[PostSetup] = ()) -> None:
        self.cache_dir = Path(cache_dir).expanduser().resolve()
        self.install_dir = Path(install_dir).expanduser().resolve() if install_dir is not None else None
        if self.install_dir is not None and (
            self.install_dir.is_relative_to(self.cache_dir) or self.cache_dir.is_relative_to(self.install_dir)
        ):
            raise ResourceError(f"cache dir {self.cache_dir} and install dir {self.install_dir} must not overlap")
        self.remote = open_remote(remote) if isinstance(remote, (str, os.PathLike)) else remote
        self.use_lock, self.workers, self.lock_timeout = use_lock, max(1, workers), lock_timeout
        self.progress = progress
        self.post_setup: list[PostSetup] = list(post_setup)
        self._pid = os.getpid()
        self._indexes: dict[ResourceSpec, PathIndex] = {}
        self._manifests: dict[ResourceSpec, dict] = {}
        self._locks: dict[str, FileLock] = {}
        self._place_lock = threading.Lock()  # one archive moves into a version dir at a time

    # -- paths -------------------------------------------------------------------------
    def version_dir(self, spec: ResourceSpec | str) -> Path:
        return self.cache_dir / ResourceSpec.parse(spec).rel

    @property
    def install_root(self) -> Path:
        """The install dir; :class:`ResourceError` when none is configured."""
        if self.install_dir is None:
            raise ResourceError("no install dir configured")
        return self.install_dir

    def require_remote(self) -> Remote:
        """The remote; :class:`ResourceError` when none was given."""
        if self.remote is None:
            raise ResourceError(f"no remote was given (cache {self.cache_dir})")
        return self.remote

    def link_path(self, spec: ResourceSpec | str) -> Path:
        spec = ResourceSpec.parse(spec)
        return self.install_root / spec.data_type / spec.source

    def meta_dir(self, spec: ResourceSpec | str) -> Path:
        """Bookkeeping dir of a version (manifest, index, flags); libraries may keep derived data here."""
        spec = ResourceSpec.parse(spec)
        return self.cache_dir / META / spec.rel

    def _fork_check(self) -> None:
        """Drop LMDB handles and caches inherited through fork (they must not be shared)."""
        if os.getpid() != self._pid:
            self._indexes, self._manifests, self._locks, self._pid = {}, {}, {}, os.getpid()
            self._place_lock = threading.Lock()

    def _root(self, path: Path) -> Path:
        """The cache or install dir ``path`` lies in: writes walk from there without following links."""
        for root in (self.cache_dir, self.install_dir):
            if root is not None and path.is_relative_to(root):
                return root
        raise ValueError(f"{path} is neither in cache dir {self.cache_dir} nor in install dir {self.install_dir}")

    # -- locks -------------------------------------------------------------------------
    @contextlib.contextmanager
    def lock(self, path: Path) -> Iterator[None]:
        """An inter-process file lock, reentrant within a thread (one FileLock object per path)."""
        if not self.use_lock:
            yield
            return
        root = self._root(path)
        os.close(fileio.open_fd(path, os.O_RDWR | os.O_CREAT, root=root))  # FileLock would follow a link
        lock = self._locks.setdefault(str(path), FileLock(str(path), timeout=self.lock_timeout))
        try:
            lock.acquire()
        except Timeout:
            raise StaleLockError(_lock_message(path, self.lock_timeout)) from None
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

    def _version_lock(self, spec: ResourceSpec):
        return self.lock(self.cache_dir / META / "locks" / f"{spec.data_type}+{spec.source}+{spec.version}.lock")

    def _install_lock(self):
        assert self.install_dir is not None
        return self.lock(self.install_dir / META / "install.lock")

    # -- metadata ----------------------------------------------------------------------
    def manifest(self, spec: ResourceSpec | str) -> dict:
        """The version's manifest (fetched from the remote on first use)."""
        self._fork_check()
        spec = ResourceSpec.parse(spec)
        if spec not in self._manifests:
            path = self.meta_dir(spec) / "manifest.json"
            if not path.is_file():
                if not self.use_lock:
                    raise ResourceError(f"{spec} is not in cache {self.cache_dir}; a leader must install it first "
                                        "(no-lock mode never installs)")
                with self._version_lock(spec):
                    self._fetch_meta(spec)
            self._manifests[spec] = parse_manifest(read_json(path), f"{spec}: cached manifest {path}")
        return self._manifests[spec]

    def _fetch_meta(self, spec: ResourceSpec) -> None:
        """Fetch and check the version's metadata into ``meta_dir``, probing :data:`LAYOUTS` in order.

        A version dir another tool filled (its metadata files inside) is adopted without asking the remote.
        """
        if (self.meta_dir(spec) / "manifest.json").is_file():
            return
        tmp = fileio.make_dirs(self.meta_dir(spec) / "tmp", root=self.cache_dir)
        if any(layout.adopt(self, spec) for layout in LAYOUTS):
            return
        if self.remote is None:
            raise ResourceError(f"{spec} is not in cache {self.cache_dir} and no remote was given")
        if not any(layout.fetch_meta(self, spec, tmp) for layout in LAYOUTS):
            raise ResourceError(f"remote {self.remote.url} has no {spec} ({self._remote_versions(spec)})")

    def _remote_versions(self, spec: ResourceSpec) -> str:
        try:
            files = self.require_remote().list_files(f"{spec.data_type}/{spec.source}")
        except ResourceError:
            return "the remote cannot be listed"
        versions = sorted({p.split("/")[2] for p in files if p.count("/") >= 3})
        return f"versions there: {', '.join(versions) or 'none'}"

    def layout(self, spec: ResourceSpec | str) -> Layout:
        """The layout of a version, by its manifest's ``format``."""
        spec = ResourceSpec.parse(spec)
        fmt = self.manifest(spec).get("format")
        return next((layout for layout in LAYOUTS if layout.format == fmt), OwnLayout)(self, spec)

    def index(self, spec: ResourceSpec | str) -> PathIndex:
        """The version's LMDB index (built from ``index.json.gz`` on first use)."""
        self._fork_check()
        spec = ResourceSpec.parse(spec)
        if spec in self._indexes:
            return self._indexes[spec]
        manifest = self.manifest(spec)
        idx = PathIndex(self.meta_dir(spec) / "index.lmdb")
        try:
            _ = idx.env  # opening it checks it is there and complete
        except ResourceError:
            if not self.use_lock:
                raise ResourceError(f"{spec}: index missing or incomplete in {self.cache_dir}; "
                                    "a leader must install it first (no-lock mode)") from None
            with self._version_lock(spec):
                try:
                    _ = idx.env  # another process may have built it while we waited
                except ResourceError:
                    path = self.meta_dir(spec) / "index.json.gz"
                    entries = check_index(read_json(path, f"{spec}: {path}"), manifest["archives"], f"{spec}: {path}")
                    fileio.make_dirs(idx.path.parent, root=self.cache_dir)  # LMDB writes in there itself
                    idx = PathIndex.build(idx.path, entries, uid_depth=manifest["uid_depth"])
        self._indexes[spec] = idx
        return idx

    def _done(self, spec: ResourceSpec) -> set[str]:
        return self.layout(spec).done()

    def is_complete(self, spec: ResourceSpec | str) -> bool:
        spec = ResourceSpec.parse(spec)
        if (self.meta_dir(spec) / "complete").is_file():
            return True
        return (self.meta_dir(spec) / "manifest.json").is_file() and self.layout(spec).complete()

    # -- install -----------------------------------------------------------------------
    def install(self, spec: ResourceSpec | str, on_demand: bool = False) -> InstallResult:
        """Install a version: eagerly (every archive now) or on demand (manifest and index only)."""
        self._fork_check()
        spec = ResourceSpec.parse(spec)
        if not self.use_lock:
            manifest = self.manifest(spec)
            if not on_demand and not self.is_complete(spec):
                raise ResourceError(f"{spec} is only partly installed in {self.cache_dir}; "
                                    "no-lock mode never installs (run the install without --no-lock first)")
            self.index(spec)
            path = self._installed_path(spec)
            return InstallResult(spec, path, 0, len(self._done(spec) & set(manifest["archives"])), on_demand)
        with self._version_lock(spec):
            self._clean_tmp(spec)
            self._fetch_meta(spec)
            manifest = self.manifest(spec)
            self.index(spec)
            layout = self.layout(spec)
            with layout.lock():
                layout.prepare()
                done = layout.done()
                todo = [] if on_demand else [a for a in manifest["archives"] if a not in done]
                self._extract(spec, todo)
                self._mark_complete(spec)
                self._record_cache(spec)
        path = self._link(spec) if self.install_dir is not None else self.version_dir(spec)
        for hook in self.post_setup:
            hook(self, spec, path)
        return InstallResult(spec, path, len(todo), len(done), on_demand)

    def _installed_path(self, spec: ResourceSpec) -> Path:
        if self.install_dir is not None and self.linked().get(spec.data_type, {}).get(spec.source) == spec.version:
            return self.link_path(spec)
        return self.version_dir(spec)

    def ensure_archives(self, spec: ResourceSpec | str, archives: Iterable[str]) -> int:
        """Install the named archives if missing (on-demand mode); returns how many were extracted."""
        self._fork_check()
        spec = ResourceSpec.parse(spec)
        wanted = [a for a in dict.fromkeys(archives) if a not in self._done(spec)]
        if not wanted:
            return 0
        if not self.use_lock:
            raise ResourceError(f"{spec}: archive {wanted[0]} is not in cache {self.cache_dir}; "
                                "no-lock mode never installs")
        with self._version_lock(spec), self.layout(spec).lock():
            todo = [a for a in wanted if a not in self._done(spec)]
            self._clean_tmp(spec)
            self._extract(spec, todo)
            self._mark_complete(spec)
        if self.install_dir is not None and self.linked().get(spec.data_type, {}).get(spec.source) == spec.version:
            self._link(spec)
        return len(todo)

    def ensure_path(self, spec: ResourceSpec | str, path: str) -> Path:
        """The cache path of ``path`` inside the version, installing its archive first if needed."""
        spec = ResourceSpec.parse(spec)
        archive = self.index(spec).archive_for_path(path)
        if archive is None:
            raise ResourceError(f"{spec}: no archive holds {path!r}")
        self.ensure_archives(spec, [archive])
        return self.version_dir(spec) / path.strip("/")

    def ensure_uid(self, spec: ResourceSpec | str, uid: str) -> list[Path]:
        """Install the archives holding ``uid``; returns the cache paths of its files."""
        spec = ResourceSpec.parse(spec)
        index = self.index(spec)
        archives = index.archives_for_uid(uid)
        if not archives:
            raise ResourceError(f"{spec}: no archive holds UID {uid!r}")
        self.ensure_archives(spec, archives)
        depth = index.meta()["uid_depth"]
        return [self.version_dir(spec) / rel for a in archives for rel in index.files(a) if uid_of(rel, depth) == uid]

    def _clean_tmp(self, spec: ResourceSpec) -> None:
        """Remove what a killed install left behind (we hold the version lock)."""
        fileio.rmtree(self.meta_dir(spec) / "tmp", root=self.cache_dir, onexc=_force_remove)

    def _mark_complete(self, spec: ResourceSpec) -> None:
        if set(self.manifest(spec)["archives"]) <= self._done(spec):
            atomic_write(self.meta_dir(spec) / "complete", "1", root=self.cache_dir)

    def _extract(self, spec: ResourceSpec, archives: list[str]) -> None:
        """Download, verify and extract ``archives`` on a thread pool, with one retry pass."""
        if not archives:
            return
        if self.remote is None:
            raise ResourceError(f"{spec}: {len(archives)} archives missing from cache and no remote was given")
        from tqdm.auto import tqdm

        entries = self.manifest(spec)["archives"]
        show = self.progress if self.progress is not None else _is_tty()
        bar = tqdm(total=sum(entries[a]["size"] for a in archives), unit="B", unit_scale=True,
                   desc=f"install {spec}", disable=not show, leave=False)
        bar_lock = threading.Lock()

        def one(name: str) -> None:
            self._install_archive(spec, name, entries[name])
            with bar_lock:
                bar.update(entries[name]["size"])

        pending = list(archives)
        try:
            for attempt in range(2):
                errors: dict[str, BaseException] = {}
                with ThreadPoolExecutor(min(self.workers, len(pending))) as pool:
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

    def _install_archive(self, spec: ResourceSpec, name: str, entry: dict) -> None:
        """Download, verify, extract (never past the index) and move one archive into place.

        Only the download and its checks may be retried: once an archive with the manifest's
        checksum fails to extract or place, the same bytes would fail again.
        """
        files = self.index(spec).files(name)
        tmp = fileio.make_dirs(self.meta_dir(spec) / "tmp", root=self.cache_dir)
        token = uuid.uuid4().hex
        part, xdir = tmp / f"{token}.part", tmp / f"x-{token}"
        layout = self.layout(spec)
        try:
            inflated = self.require_remote().fetch_archive(spec.rel, name, part, layout.format)
            limit = layout.check_download(part, name, entry, files, inflated)
            try:
                safe_extract(part, xdir, name, files, limit, root=self.cache_dir)
                self._place(spec, name, xdir, files)
            except ResourceError as exc:
                exc.retryable = False
                raise
            layout.mark_done(name, entry)
        finally:
            fileio.remove(part, root=self.cache_dir)
            fileio.rmtree(xdir, root=self.cache_dir, onexc=_force_remove)

    def _place(self, spec: ResourceSpec, name: str, xdir: Path, files: dict[str, list]) -> None:
        """Move an extracted archive into the version dir without following any link, then check
        every link of the version against the real tree; on a problem, take the archive out again."""
        vdir = self.version_dir(spec)
        where = f"archive {name}"
        with self._place_lock, fileio.open_dir(xdir, root=self.cache_dir, create=False) as xroot, \
                fileio.open_dir(vdir, root=self.cache_dir) as vroot:
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
                self._check_links(spec, [r for r in placed if files[r][0] in ("->", None)], where)
            except BaseException as exc:
                for rel in placed:
                    fileio.remove_at(vroot, rel)
                if isinstance(exc, UnsafePathError):
                    raise UnsafeArchiveError(str(exc)) from None
                raise

    def _check_links(self, spec: ResourceSpec, new: list[str], where: str) -> None:
        """Every link of the version must resolve, through the real tree, inside the version dir.

        A new link can change where an older one leads (``a -> .`` makes ``b -> a/..`` escape),
        so all links placed so far are rechecked whenever an archive brings links.
        """
        vdir = self.version_dir(spec)
        new = [r for r in new if os.path.islink(vdir / r)]
        if not new:
            return
        path = self.meta_dir(spec) / "links.json"
        known = read_json(path) if path.is_file() else []
        known = known if isinstance(known, list) else []
        links = sorted({r for r in known if isinstance(r, str) and os.path.islink(vdir / r)} | set(new))
        bad = [r for r in links if not fileio.resolves_inside(vdir, r)]
        if bad:
            raise UnsafeArchiveError(f"{where}: link {bad[0]!r} -> {os.readlink(vdir / bad[0])!r} resolves to "
                                     f"{os.path.realpath(vdir / bad[0])}, outside {vdir}, through the links of "
                                     "this version; refusing to install")
        atomic_write(path, json.dumps(links), root=self.cache_dir)

    # -- links -------------------------------------------------------------------------
    def _link(self, spec: ResourceSpec) -> Path:
        """Point ``<install>/<data_type>/<source>`` at this version (re-pointing an older one)."""
        link = self.link_path(spec)
        target = self.version_dir(spec)
        mode = self.manifest(spec)["link"]
        layout = self.layout(spec)
        install = self.install_root
        with self._install_lock(), layout.link_lock():
            fileio.make_dirs(link.parent, root=install)
            current = self.linked().get(spec.data_type, {}).get(spec.source)
            token = uuid.uuid4().hex
            if mode == "dir":
                if not (link.is_symlink() and os.readlink(link) == str(target)):
                    fileio.make_dirs(target, root=self.cache_dir)
                    tmp = link.parent / f".{link.name}.{token}.link"
                    fileio.symlink(target, tmp, root=install)
                    if link.is_dir() and not link.is_symlink():
                        _remove_link_tree(link, install)
                    fileio.replace(tmp, link, root=install)
            else:
                index, done = self.index(spec), sorted(self._done(spec) & set(self.manifest(spec)["archives"]))
                files = [rel for a in done for rel in index.files(a)] + layout.link_files()
                if current == spec.version and link.is_dir() and not link.is_symlink():
                    _make_links(link, target, files, install)  # same version: add what on-demand installs brought
                    layout.flag_links(link, done)
                else:
                    new = link.parent / f".{link.name}.{token}.new"
                    _make_links(new, target, files, install)
                    layout.flag_links(new, done)
                    if link.is_symlink():
                        fileio.remove(link, root=install)
                    elif link.exists():
                        old = link.parent / f".{link.name}.{token}.old"
                        fileio.replace(link, old, root=install)
                        fileio.replace(new, link, root=install)
                        _remove_link_tree(old, install)
                    if not link.exists():
                        fileio.replace(new, link, root=install)
            def point(d: dict) -> None:
                d.setdefault(spec.data_type, {})[spec.source] = spec.version

            self.update_json(install / META / "installed.json", point, "str")
            layout.record_link(point, current)
        return link

    # -- local manifests ---------------------------------------------------------------
    def _record_cache(self, spec: ResourceSpec) -> None:
        def add(d: dict) -> None:
            versions = d.setdefault(spec.data_type, {}).setdefault(spec.source, [])
            if spec.version not in versions:
                versions.append(spec.version)
                versions.sort()

        with self.lock(self.cache_dir / META / "locks" / "manifest.lock"):
            self.update_json(self.cache_dir / META / "installed.json", add, "list")
            self.layout(spec).record_cache(add)  # under the layout's lock (held by the caller)

    def update_json(self, path: Path, edit: Callable[[dict], None], values: Literal["list", "str"],
                    indent: int = 1) -> None:
        """Edit a version record ``{type: {source: values}}`` (``values``: ``"list"`` or ``"str"``) in place;
        ours sorted with ``indent`` 1, another tool's as it writes them."""
        data = check_local(read_json(path), path, values) if path.is_file() else {}
        edit(data)
        atomic_write(path, json.dumps(data, indent=indent, sort_keys=indent == 1), root=self._root(path))

    @staticmethod
    def _records(root: Path) -> list[Path]:
        """Ours and every layout's version records at the root of the cache or install dir (later ones win)."""
        return [root / META / "installed.json", *(path for layout in LAYOUTS for path in layout.records(root))]

    def installed(self) -> dict[str, dict[str, list[str]]]:
        """``{data_type: {source: [versions]}}`` present in the cache (ours and molmospaces-resources')."""
        out: dict[str, dict[str, list[str]]] = {}
        for path in self._records(self.cache_dir):
            if path.is_file():
                for data_type, sources in check_local(read_json(path), path, "list").items():
                    for source, versions in sources.items():
                        have = out.setdefault(data_type, {}).setdefault(source, [])
                        have[:] = sorted(set(have) | set(versions))
        return {t: {s: v for s, v in src.items() if v} for t, src in out.items() if any(src.values())}

    def linked(self) -> dict[str, dict[str, str]]:
        """``{data_type: {source: version}}`` the install dir points at (molmospaces-resources' record wins)."""
        if self.install_dir is None:
            return {}
        out: dict[str, dict[str, str]] = {}
        for path in self._records(self.install_dir):
            if path.is_file():
                for data_type, sources in check_local(read_json(path), path, "str").items():
                    out.setdefault(data_type, {}).update({s: v for s, v in sources.items() if v is not None})
        return {t: src for t, src in out.items() if src}

    # -- verification ------------------------------------------------------------------
    def verify(self) -> list[str]:
        """Recheck every installed file (size, sha256, read-only) and link; returns the problems found."""
        self._fork_check()
        problems: list[str] = []
        for data_type, sources in sorted(self.installed().items()):
            for source, versions in sorted(sources.items()):
                for version in versions:
                    spec = ResourceSpec(data_type, source, version)
                    problems += self._verify_version(spec)
        for data_type, links in sorted(self.linked().items()):
            for source, version in sorted(links.items()):
                spec = ResourceSpec(data_type, source, version)
                link = self.link_path(spec)
                if not link.exists():
                    problems.append(f"{spec}: install link {link} is missing or dangling")
                elif self.manifest(spec)["link"] == "dir" and Path(os.path.realpath(link)) != self.version_dir(spec):
                    problems.append(f"{spec}: {link} does not point at {self.version_dir(spec)}")
        return problems

    def _verify_version(self, spec: ResourceSpec) -> list[str]:
        """Compare the real tree (walked without following links) with the index of its done archives."""
        try:
            manifest, index = self.manifest(spec), self.index(spec)
        except ResourceError as exc:
            return [f"{spec}: {exc}"]
        layout = self.layout(spec)
        done = layout.done()
        problems = []
        if self.is_complete(spec) and not set(manifest["archives"]) <= done:
            problems.append(f"{spec}: marked complete but archives are missing")
        vdir = self.version_dir(spec)
        tree = fileio.walk(vdir) if vdir.is_dir() and not vdir.is_symlink() else {}
        expected: dict[str, tuple[str, list]] = {}
        for archive in sorted(done & set(manifest["archives"])):
            expected.update((rel, (archive, want)) for rel, want in index.files(archive).items())
        dirs = {p for rel in expected for p in PurePosixPath(rel).parents if str(p) != "."}
        for rel, (archive, want) in sorted(expected.items()):
            got, what = tree.get(rel), f"{spec}: {rel} (archive {archive})"
            if want[0] == "->":
                if got != ("l", want[1]):
                    problems.append(f"{what} is not the link to {want[1]!r}")
            elif want[0] is None:  # MolmoSpaces' index: no size or checksum to compare
                if got is None:
                    problems.append(f"{what} is missing")
                elif got[0] == "f" and (vdir / rel).stat().st_mode & 0o222:
                    problems.append(f"{what} is writable")
            elif got is None or got[0] != "f":
                problems.append(f"{what} is missing")
            elif got[1] != want[0] or sha256_file(vdir / rel) != want[1]:
                problems.append(f"{what} differs from the manifest")
            elif (vdir / rel).stat().st_mode & 0o222:
                problems.append(f"{what} is writable")
        for rel, got in sorted(tree.items()):
            if rel not in expected and not (got == ("d",) and PurePosixPath(rel) in dirs) and not layout.own_file(rel):
                problems.append(f"{spec}: {rel} is not in the index of any installed archive")
            if got[0] == "l" and not fileio.resolves_inside(vdir, rel):
                problems.append(f"{spec}: link {rel} -> {got[1]!r} resolves to {os.path.realpath(vdir / rel)}, "
                                f"outside {vdir}")
        return problems


# -- packing -------------------------------------------------------------------------------
def pack(src: str | os.PathLike, remote: Remote | str | os.PathLike, spec: ResourceSpec | str, *,
         link: str = "dir", uid_depth: int = 0, max_archive_bytes: int = 64 << 20) -> dict:
    """Archive the tree ``src`` into ``remote`` as one new version; returns the manifest.

    Files are grouped by their path prefix up to the UID component (so one UID never spans
    archives) and the groups filled into archives of about ``max_archive_bytes``.
    """
    spec = ResourceSpec.parse(spec)
    if link not in LINK_MODES:
        raise ResourceError(f"link mode {link!r} is not one of {LINK_MODES}")
    remote = open_remote(remote) if isinstance(remote, (str, os.PathLike)) else remote
    root = Path(src).expanduser().resolve()
    entries = tree_entries(root)
    if not entries:
        raise ResourceError(f"{root}: nothing to pack")
    groups: dict[str, list[str]] = {}
    for rel in entries:
        groups.setdefault("/".join(PurePosixPath(rel).parts[: uid_depth + 1]), []).append(rel)
    parts: list[list[str]] = [[]]
    size = 0
    for paths in groups.values():
        group_size = sum(entries[p][0] for p in paths if entries[p][0] != "->")
        if parts[-1] and size + group_size > max_archive_bytes:
            parts.append([])
            size = 0
        parts[-1].extend(paths)
        size += group_size
    with tempfile.TemporaryDirectory(prefix="molmo-pack-") as tmp:
        staging = Path(tmp) / "version"
        fileio.make_dirs(staging / "archives", root=tmp)
        archives, index = {}, {}
        for i, paths in enumerate(parts):
            name = f"{spec.source}-{spec.version}-{i:05d}.tar.zst"
            info = pack_archive(root, paths, staging / "archives" / name)
            archives[name] = {**info, "n_files": len(paths)}
            index[name] = {p: entries[p] for p in paths}
        manifest = {"format": 1, "data_type": spec.data_type, "source": spec.source, "version": spec.version,
                    "link": link, "uid_depth": uid_depth, "archives": archives}
        with atomic_open(staging / "index.json.gz", "wb", root=tmp) as raw, \
                gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as fh:
            fh.write(json.dumps(index, sort_keys=True).encode())
        atomic_write(staging / "manifest.json", json.dumps(manifest, indent=1, sort_keys=True), root=tmp)
        remote.upload_dir(staging, spec.rel, message=f"Add {spec}")
    return manifest


# -- helpers ------------------------------------------------------------------------------
def _lock_message(path: Path, timeout: float) -> str:
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


def _is_tty() -> bool:
    import sys

    return sys.stderr.isatty()


def _make_links(root: Path, target: Path, files: Iterable[str], install: Path) -> None:
    """Per-file links ``root/rel -> target/rel``, made without following any link below ``install``."""
    with fileio.open_dir(root, root=install) as rfd:
        for rel in files:
            with fileio.parent_of(rfd, rel, create=True, where=f"install dir {root}") as (fd, leaf):
                if fileio.lstat_at(fd, leaf) is None:
                    os.symlink(target / rel, leaf, dir_fd=fd)


def _remove_link_tree(path: Path, install: Path) -> None:
    """Delete a tree of links made by :func:`_make_links` (and a layout's flags), refusing one that holds real files."""
    for dirpath, _dirnames, filenames in os.walk(path):
        for name in filenames:
            if dirpath == str(path) and any(layout.own_link_file(name) for layout in LAYOUTS):
                continue
            if not os.path.islink(os.path.join(dirpath, name)):
                raise ResourceError(f"{path} holds real files ({name}); refusing to replace it with links")
    fileio.rmtree(path, root=install)


def _force_remove(func, path, _exc: BaseException) -> None:
    """``rmtree`` error handler: make read-only entries writable and retry."""
    with contextlib.suppress(OSError):
        os.chmod(os.path.dirname(path), 0o755)
        os.chmod(path, 0o755)
        func(path)


__all__ = ["InstallResult", "PostSetup", "ResourceManager", "ResourceSpec", "pack"]
