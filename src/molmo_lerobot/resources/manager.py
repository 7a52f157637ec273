"""The resource manager: a versioned read-only cache and a version-free install dir of links.

Cache ``<cache>/<data_type>/<source>/<version>/`` holds exactly the packed tree, files
read-only; bookkeeping lives beside it in ``<cache>/.molmo/`` (manifests, LMDB index,
per-archive completion flags, locks, temporary extraction dirs). The install dir holds
``<install>/<data_type>/<source>`` — one link to the version dir (``link="dir"``) or a tree
of per-file links (``link="file"``, so relative MJCF paths resolve). Upgrades re-point links.
"""

from __future__ import annotations

import contextlib
import gzip
import json
import os
import re
import shutil
import socket
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from filelock import FileLock, Timeout

from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.resources.archive import pack_archive, safe_extract, sha256_file, tree_entries, verify_archive
from molmo_lerobot.resources.errors import (
    CorruptArchiveError,
    ResourceError,
    StaleLockError,
    UnsafeArchiveError,
)
from molmo_lerobot.resources.index import PathIndex, uid_of
from molmo_lerobot.resources.remotes import Remote, open_remote

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
LINK_MODES = ("dir", "file")
META = ".molmo"


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

    # -- paths -------------------------------------------------------------------------
    def version_dir(self, spec: ResourceSpec | str) -> Path:
        return self.cache_dir / ResourceSpec.parse(spec).rel

    def link_path(self, spec: ResourceSpec | str) -> Path:
        spec = ResourceSpec.parse(spec)
        if self.install_dir is None:
            raise ResourceError("no install dir configured")
        return self.install_dir / spec.data_type / spec.source

    def meta_dir(self, spec: ResourceSpec | str) -> Path:
        """Bookkeeping dir of a version (manifest, index, flags); libraries may keep derived data here."""
        spec = ResourceSpec.parse(spec)
        return self.cache_dir / META / spec.rel

    def _fork_check(self) -> None:
        """Drop LMDB handles and caches inherited through fork (they must not be shared)."""
        if os.getpid() != self._pid:
            self._indexes, self._manifests, self._locks, self._pid = {}, {}, {}, os.getpid()

    # -- locks -------------------------------------------------------------------------
    @contextlib.contextmanager
    def _lock(self, path: Path) -> Iterator[None]:
        """An inter-process file lock, reentrant within a thread (one FileLock object per path)."""
        if not self.use_lock:
            yield
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        lock = self._locks.setdefault(str(path), FileLock(str(path), timeout=self.lock_timeout))
        try:
            lock.acquire()
        except Timeout:
            raise StaleLockError(_lock_message(path, self.lock_timeout)) from None
        owner = Path(f"{path}.owner")
        try:
            if lock.lock_counter == 1:
                owner.write_text(json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "since": time.time()}))
            yield
        finally:
            if lock.lock_counter == 1:
                with contextlib.suppress(OSError):
                    owner.unlink()
            lock.release()

    def _version_lock(self, spec: ResourceSpec):
        return self._lock(self.cache_dir / META / "locks" / f"{spec.data_type}+{spec.source}+{spec.version}.lock")

    def _install_lock(self):
        assert self.install_dir is not None
        return self._lock(self.install_dir / META / "install.lock")

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
            self._manifests[spec] = json.loads(path.read_text())
        return self._manifests[spec]

    def _fetch_meta(self, spec: ResourceSpec) -> None:
        meta = self.meta_dir(spec)
        if (meta / "manifest.json").is_file():
            return
        if self.remote is None:
            raise ResourceError(f"{spec} is not in cache {self.cache_dir} and no remote was given")
        tmp = meta / "tmp"
        tmp.mkdir(parents=True, exist_ok=True)
        try:
            self.remote.download(f"{spec.rel}/manifest.json", tmp / "manifest.json")
            self.remote.download(f"{spec.rel}/index.json.gz", tmp / "index.json.gz")
        except ResourceError:
            versions = sorted({p.split("/")[2] for p in self.remote.list_files(f"{spec.data_type}/{spec.source}")
                               if p.count("/") >= 3})
            raise ResourceError(f"remote {self.remote.url} has no {spec} "
                                f"(versions there: {', '.join(versions) or 'none'})") from None
        manifest = _read_json(tmp / "manifest.json", "manifest")
        for key in ("archives", "link", "uid_depth"):
            if key not in manifest:
                raise ResourceError(f"{spec}: remote manifest.json lacks field {key!r}")
        if (manifest.get("data_type"), manifest.get("source"), manifest.get("version")) != (
                spec.data_type, spec.source, spec.version):
            raise ResourceError(f"{spec}: remote manifest.json describes another resource")
        if manifest["link"] not in LINK_MODES:
            raise ResourceError(f"{spec}: manifest.json field 'link' is {manifest['link']!r}, not one of {LINK_MODES}")
        os.replace(tmp / "index.json.gz", meta / "index.json.gz")
        os.replace(tmp / "manifest.json", meta / "manifest.json")  # last: its presence means meta is complete

    def index(self, spec: ResourceSpec | str) -> PathIndex:
        """The version's LMDB index (built from ``index.json.gz`` on first use)."""
        self._fork_check()
        spec = ResourceSpec.parse(spec)
        if spec in self._indexes:
            return self._indexes[spec]
        manifest = self.manifest(spec)
        idx = PathIndex(self.meta_dir(spec) / "index.lmdb")
        try:
            idx.env
        except ResourceError:
            if not self.use_lock:
                raise ResourceError(f"{spec}: index missing or incomplete in {self.cache_dir}; "
                                    "a leader must install it first (no-lock mode)") from None
            with self._version_lock(spec):
                try:
                    idx.env  # another process may have built it while we waited
                except ResourceError:
                    entries = json.loads(gzip.decompress((self.meta_dir(spec) / "index.json.gz").read_bytes()))
                    if set(entries) != set(manifest["archives"]):
                        raise ResourceError(f"{spec}: index.json.gz and manifest.json list different archives") from None
                    idx = PathIndex.build(idx.path, entries, uid_depth=manifest["uid_depth"])
        self._indexes[spec] = idx
        return idx

    def _done(self, spec: ResourceSpec) -> set[str]:
        done = self.meta_dir(spec) / "done"
        return {p.name[:-3] for p in done.glob("*.ok")} if done.is_dir() else set()

    def is_complete(self, spec: ResourceSpec | str) -> bool:
        return (self.meta_dir(ResourceSpec.parse(spec)) / "complete").is_file()

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
            done = self._done(spec)
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
        with self._version_lock(spec):
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
        tmp = self.meta_dir(spec) / "tmp"
        if tmp.exists():
            shutil.rmtree(tmp, onexc=_force_remove)

    def _mark_complete(self, spec: ResourceSpec) -> None:
        if set(self.manifest(spec)["archives"]) <= self._done(spec):
            atomic_write(self.meta_dir(spec) / "complete", "1", parents=True)

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
                fatal = [e for e in errors.values() if isinstance(e, UnsafeArchiveError)]
                if not errors or fatal or attempt == 1:
                    break
                pending = list(errors)
        finally:
            bar.close()
        if errors:
            first = (fatal or list(errors.values()))[0]
            if isinstance(first, ResourceError):
                raise first
            raise ResourceError(f"{spec}: installing {len(errors)} archive(s) failed: {first}") from first

    def _install_archive(self, spec: ResourceSpec, name: str, entry: dict) -> None:
        files = self.index(spec).files(name)
        tmp = self.meta_dir(spec) / "tmp"
        tmp.mkdir(parents=True, exist_ok=True)
        token = uuid.uuid4().hex
        part, xdir = tmp / f"{token}.part", tmp / f"x-{token}"
        try:
            self.remote.download(f"{spec.rel}/archives/{name}", part)
            verify_archive(part, name, entry["size"], entry["sha256"])
            safe_extract(part, xdir, name)
            got = _walk(xdir)
            if set(got) != set(files):
                missing, extra = sorted(set(files) - set(got)), sorted(set(got) - set(files))
                raise CorruptArchiveError(f"archive {name}: contents differ from the index "
                                          f"(missing {missing[:3]}, unexpected {extra[:3]})")
            for rel, want in files.items():
                if want[0] != "->" and got[rel] != want[0]:
                    raise CorruptArchiveError(f"archive {name}: {rel} has size {got[rel]}, index says {want[0]}")
            vdir = self.version_dir(spec)
            for rel in sorted(files):
                src, dest = xdir / rel, vdir / rel
                dest.parent.mkdir(parents=True, exist_ok=True)
                if not src.is_symlink():
                    os.chmod(src, 0o444)
                if dest.is_dir() and not dest.is_symlink():
                    raise ResourceError(f"archive {name}: {rel} would replace a directory in {vdir}")
                os.replace(src, dest)
            atomic_write(self.meta_dir(spec) / "done" / f"{name}.ok", entry["sha256"], parents=True)
        finally:
            with contextlib.suppress(FileNotFoundError):
                part.unlink()
            if xdir.exists():
                shutil.rmtree(xdir, onexc=_force_remove)

    # -- links -------------------------------------------------------------------------
    def _link(self, spec: ResourceSpec) -> Path:
        """Point ``<install>/<data_type>/<source>`` at this version (re-pointing an older one)."""
        link = self.link_path(spec)
        target = self.version_dir(spec)
        mode = self.manifest(spec)["link"]
        with self._install_lock():
            link.parent.mkdir(parents=True, exist_ok=True)
            current = self.linked().get(spec.data_type, {}).get(spec.source)
            token = uuid.uuid4().hex
            if mode == "dir":
                if not (link.is_symlink() and os.readlink(link) == str(target)):
                    target.mkdir(parents=True, exist_ok=True)
                    tmp = link.parent / f".{link.name}.{token}.link"
                    os.symlink(target, tmp, target_is_directory=True)
                    if link.is_dir() and not link.is_symlink():
                        _remove_link_tree(link)
                    os.replace(tmp, link)
            else:
                index, done = self.index(spec), self._done(spec)
                files = [rel for a in sorted(done & set(self.manifest(spec)["archives"])) for rel in index.files(a)]
                if current == spec.version and link.is_dir() and not link.is_symlink():
                    _make_links(link, target, files)  # same version: add what on-demand installs brought
                else:
                    new = link.parent / f".{link.name}.{token}.new"
                    _make_links(new, target, files)
                    if link.is_symlink():
                        link.unlink()
                    elif link.exists():
                        old = link.parent / f".{link.name}.{token}.old"
                        os.replace(link, old)
                        os.replace(new, link)
                        _remove_link_tree(old)
                    if not link.exists():
                        os.replace(new, link)
            self._update_json(self.install_dir / META / "installed.json",
                              lambda d: d.setdefault(spec.data_type, {}).__setitem__(spec.source, spec.version))
        return link

    # -- local manifests ---------------------------------------------------------------
    def _record_cache(self, spec: ResourceSpec) -> None:
        def add(d: dict) -> None:
            versions = d.setdefault(spec.data_type, {}).setdefault(spec.source, [])
            if spec.version not in versions:
                versions.append(spec.version)
                versions.sort()

        with self._lock(self.cache_dir / META / "locks" / "manifest.lock"):
            self._update_json(self.cache_dir / META / "installed.json", add)

    @staticmethod
    def _update_json(path: Path, edit: Callable[[dict], None]) -> None:
        data = json.loads(path.read_text()) if path.is_file() else {}
        edit(data)
        atomic_write(path, json.dumps(data, indent=1, sort_keys=True), parents=True)

    def installed(self) -> dict[str, dict[str, list[str]]]:
        """``{data_type: {source: [versions]}}`` present in the cache."""
        path = self.cache_dir / META / "installed.json"
        return json.loads(path.read_text()) if path.is_file() else {}

    def linked(self) -> dict[str, dict[str, str]]:
        """``{data_type: {source: version}}`` the install dir points at."""
        if self.install_dir is None:
            return {}
        path = self.install_dir / META / "installed.json"
        return json.loads(path.read_text()) if path.is_file() else {}

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
        for data_type, sources in sorted(self.linked().items()):
            for source, version in sorted(sources.items()):
                spec = ResourceSpec(data_type, source, version)
                link = self.link_path(spec)
                if not link.exists():
                    problems.append(f"{spec}: install link {link} is missing or dangling")
                elif self.manifest(spec)["link"] == "dir" and Path(os.path.realpath(link)) != self.version_dir(spec):
                    problems.append(f"{spec}: {link} does not point at {self.version_dir(spec)}")
        return problems

    def _verify_version(self, spec: ResourceSpec) -> list[str]:
        try:
            manifest, index = self.manifest(spec), self.index(spec)
        except ResourceError as exc:
            return [f"{spec}: {exc}"]
        done = self._done(spec)
        problems = []
        if self.is_complete(spec) and not set(manifest["archives"]) <= done:
            problems.append(f"{spec}: marked complete but archives are missing")
        vdir = self.version_dir(spec)
        for archive in sorted(done & set(manifest["archives"])):
            for rel, want in index.files(archive).items():
                path = vdir / rel
                if want[0] == "->":
                    if not path.is_symlink() or os.readlink(path) != want[1]:
                        problems.append(f"{spec}: {rel} (archive {archive}) is not the link to {want[1]!r}")
                    continue
                if not path.is_file() or path.is_symlink():
                    problems.append(f"{spec}: {rel} (archive {archive}) is missing")
                elif path.stat().st_size != want[0] or sha256_file(path) != want[1]:
                    problems.append(f"{spec}: {rel} (archive {archive}) differs from the manifest")
                elif path.stat().st_mode & 0o222:
                    problems.append(f"{spec}: {rel} (archive {archive}) is writable")
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
        (staging / "archives").mkdir(parents=True)
        archives, index = {}, {}
        for i, paths in enumerate(parts):
            name = f"{spec.source}-{spec.version}-{i:05d}.tar.zst"
            info = pack_archive(root, paths, staging / "archives" / name)
            archives[name] = {**info, "n_files": len(paths)}
            index[name] = {p: entries[p] for p in paths}
        manifest = {"format": 1, "data_type": spec.data_type, "source": spec.source, "version": spec.version,
                    "link": link, "uid_depth": uid_depth, "archives": archives}
        with gzip.GzipFile(staging / "index.json.gz", "wb", mtime=0) as fh:
            fh.write(json.dumps(index, sort_keys=True).encode())
        (staging / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True))
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


def _read_json(path: Path, what: str) -> dict:
    try:
        data = json.loads(path.read_text())
    except ValueError as exc:
        raise ResourceError(f"{what} {path.name} is not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ResourceError(f"{what} {path.name} must hold a JSON object")
    return data


def _walk(root: Path) -> dict[str, int | str]:
    """Files (→ size) and symlinks (→ "->") under ``root``."""
    out: dict[str, int | str] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in filenames + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
            full = os.path.join(dirpath, name)
            rel = Path(full).relative_to(root).as_posix()
            out[rel] = "->" if os.path.islink(full) else os.path.getsize(full)
    return out


def _make_links(root: Path, target: Path, files: Iterable[str]) -> None:
    root.mkdir(parents=True, exist_ok=True)
    for rel in files:
        link = root / rel
        if os.path.lexists(link):
            continue
        link.parent.mkdir(parents=True, exist_ok=True)
        os.symlink(target / rel, link)


def _remove_link_tree(path: Path) -> None:
    """Delete a tree of links made by :func:`_make_links`, refusing one that holds real files."""
    for dirpath, dirnames, filenames in os.walk(path):
        for name in filenames:
            if not os.path.islink(os.path.join(dirpath, name)):
                raise ResourceError(f"{path} holds real files ({name}); refusing to replace it with links")
    shutil.rmtree(path)


def _force_remove(func, path, _exc: BaseException) -> None:
    """``rmtree`` error handler: make read-only entries writable and retry."""
    with contextlib.suppress(OSError):
        os.chmod(os.path.dirname(path), 0o755)
        os.chmod(path, 0o755)
        func(path)


__all__ = ["InstallResult", "ResourceManager", "ResourceSpec", "pack", "PostSetup"]
