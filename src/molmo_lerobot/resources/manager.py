"""The resource manager: a versioned read-only cache and a version-free install dir of links.

Cache ``<cache>/<data_type>/<source>/<version>/`` holds exactly the packed tree, files
read-only; bookkeeping lives beside it in ``<cache>/.molmo/`` (manifests, LMDB index,
per-archive completion flags, locks, temporary extraction dirs). The install dir holds
``<install>/<data_type>/<source>`` — one link to the version dir (``link="dir"``) or a tree
of per-file links (``link="file"``, so relative MJCF paths resolve). Upgrades re-point links.
What a version's format keeps beyond that (its metadata source, done marks, archive checks, the
locks and records of another tool sharing the cache) is its :class:`~.layout.Layout`, chosen by
the manifest's ``format`` from :data:`~.formats.LAYOUTS`.

The manager holds the flow and the per-process caches (manifests, LMDB handles); the work is done
by :mod:`.locks` (inter-process file locks), :mod:`.install` (extract, place, link: never through
a link below the cache or install dir), :mod:`.verify` and :mod:`.records` (version records).
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.resources.errors import ResourceError
from molmo_lerobot.resources.formats import LAYOUTS, layout_for
from molmo_lerobot.resources.index import PathIndex, uid_of
from molmo_lerobot.resources.install import Extraction, clean_tmp, link_version
from molmo_lerobot.resources.layout import Layout
from molmo_lerobot.resources.locks import FileLocks
from molmo_lerobot.resources.manifests import check_index, parse_manifest, read_json
from molmo_lerobot.resources.records import cached_versions, linked_versions, update_record
from molmo_lerobot.resources.remotes import Remote, open_remote
from molmo_lerobot.resources.spec import META, ResourceSpec, VersionPlace
from molmo_lerobot.resources.verify import link_problems, version_problems


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
        self.use_lock, self.workers = use_lock, max(1, workers)
        self.progress = progress
        self.post_setup: list[PostSetup] = list(post_setup)
        self.locks = FileLocks((self.cache_dir, self.install_dir), enabled=use_lock, timeout=lock_timeout)
        self._pid = os.getpid()
        self._indexes: dict[ResourceSpec, PathIndex] = {}
        self._manifests: dict[ResourceSpec, dict] = {}
        self._place_lock = threading.Lock()  # one archive moves into a version dir at a time

    # -- paths -------------------------------------------------------------------------
    def place(self, spec: ResourceSpec | str) -> VersionPlace:
        """Where the version lives (what its layout, install and verification work on)."""
        return VersionPlace(ResourceSpec.parse(spec), self.cache_dir, self.install_dir)

    def version_dir(self, spec: ResourceSpec | str) -> Path:
        return self.place(spec).version_dir

    def link_path(self, spec: ResourceSpec | str) -> Path:
        return self.place(spec).link_path

    def meta_dir(self, spec: ResourceSpec | str) -> Path:
        """Bookkeeping dir of a version (manifest, index, flags); libraries may keep derived data here."""
        return self.place(spec).meta_dir

    def _fork_check(self) -> None:
        """Drop LMDB handles and caches inherited through fork (they must not be shared)."""
        if os.getpid() != self._pid:
            self._indexes, self._manifests, self._pid = {}, {}, os.getpid()
            self._place_lock = threading.Lock()

    def _version_lock(self, spec: ResourceSpec) -> contextlib.AbstractContextManager:
        return self.locks.hold(self.cache_dir / META / "locks" / f"{spec.data_type}+{spec.source}+{spec.version}.lock")

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
        place = self.place(spec)
        if (place.meta_dir / "manifest.json").is_file():
            return
        tmp = fileio.make_dirs(place.meta_dir / "tmp", root=self.cache_dir)
        if any(layout.adopt(place) for layout in LAYOUTS.values()):
            return
        if self.remote is None:
            raise ResourceError(f"{spec} is not in cache {self.cache_dir} and no remote was given")
        if not any(layout.fetch_meta(place, self.remote, tmp) for layout in LAYOUTS.values()):
            raise ResourceError(f"remote {self.remote.url} has no {spec} ({self._remote_versions(spec)})")

    def _remote_versions(self, spec: ResourceSpec) -> str:
        if self.remote is None:
            return "no remote was given"
        try:
            files = self.remote.list_files(f"{spec.data_type}/{spec.source}")
        except ResourceError:
            return "the remote cannot be listed"
        versions = sorted({p.split("/")[2] for p in files if p.count("/") >= 3})
        return f"versions there: {', '.join(versions) or 'none'}"

    def layout(self, spec: ResourceSpec | str) -> Layout:
        """The layout of a version, by its manifest's ``format``."""
        spec = ResourceSpec.parse(spec)
        manifest = self.manifest(spec)
        return layout_for(manifest.get("format"))(self.place(spec), manifest, self.locks)

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
            return InstallResult(spec, path, 0, len(self.layout(spec).done() & set(manifest["archives"])), on_demand)
        with self._version_lock(spec):
            clean_tmp(self.place(spec))
            self._fetch_meta(spec)
            manifest = self.manifest(spec)
            self.index(spec)
            layout = self.layout(spec)
            with layout.lock():
                layout.prepare()
                done = layout.done()
                todo = [] if on_demand else [a for a in manifest["archives"] if a not in done]
                self._extract(spec, todo)
                self._mark_complete(layout)
                self._record_cache(layout)
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
        wanted = [a for a in dict.fromkeys(archives) if a not in self.layout(spec).done()]
        if not wanted:
            return 0
        if not self.use_lock:
            raise ResourceError(f"{spec}: archive {wanted[0]} is not in cache {self.cache_dir}; "
                                "no-lock mode never installs")
        layout = self.layout(spec)
        with self._version_lock(spec), layout.lock():
            todo = [a for a in wanted if a not in layout.done()]
            clean_tmp(layout.place)
            self._extract(spec, todo)
            self._mark_complete(layout)
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

    def _mark_complete(self, layout: Layout) -> None:
        if set(layout.manifest["archives"]) <= layout.done():
            atomic_write(layout.place.meta_dir / "complete", "1", root=self.cache_dir)

    def _extract(self, spec: ResourceSpec, archives: list[str]) -> None:
        """Download, verify and extract ``archives`` (:class:`~.install.Extraction`)."""
        if not archives:
            return
        if self.remote is None:
            raise ResourceError(f"{spec}: {len(archives)} archives missing from cache and no remote was given")
        extraction = Extraction(self.place(spec), self.manifest(spec), self.index(spec), self.layout(spec),
                                self.remote, self._place_lock)
        extraction.run(archives, workers=self.workers, progress=self.progress)

    def _link(self, spec: ResourceSpec) -> Path:
        """Point ``<install>/<data_type>/<source>`` at this version (re-pointing an older one) and record it."""
        layout, install = self.layout(spec), self.install_dir
        assert install is not None
        with self.locks.hold(install / META / "install.lock"), layout.link_lock():
            current = self.linked().get(spec.data_type, {}).get(spec.source)
            link = link_version(layout.place, layout, self.index(spec), current)

            def point(d: dict) -> None:
                d.setdefault(spec.data_type, {})[spec.source] = spec.version

            update_record(install / META / "installed.json", point, "str", root=install)
            layout.record_link(point, current)
        return link

    # -- version records ---------------------------------------------------------------
    def _record_cache(self, layout: Layout) -> None:
        spec = layout.place.spec

        def add(d: dict) -> None:
            versions = d.setdefault(spec.data_type, {}).setdefault(spec.source, [])
            if spec.version not in versions:
                versions.append(spec.version)
                versions.sort()

        with self.locks.hold(self.cache_dir / META / "locks" / "manifest.lock"):
            update_record(self.cache_dir / META / "installed.json", add, "list", root=self.cache_dir)
            layout.record_cache(add)  # under the layout's lock (held by the caller)

    @staticmethod
    def _records(root: Path) -> list[Path]:
        """Ours and every layout's version records at the root of the cache or install dir (later ones win)."""
        return [root / META / "installed.json", *(path for layout in LAYOUTS.values() for path in layout.records(root))]

    def installed(self) -> dict[str, dict[str, list[str]]]:
        """``{data_type: {source: [versions]}}`` present in the cache (ours and molmospaces-resources')."""
        return cached_versions(self._records(self.cache_dir))

    def linked(self) -> dict[str, dict[str, str]]:
        """``{data_type: {source: version}}`` the install dir points at (molmospaces-resources' record wins)."""
        return linked_versions(self._records(self.install_dir)) if self.install_dir is not None else {}

    # -- verification ------------------------------------------------------------------
    def verify(self) -> list[str]:
        """Recheck every installed file (size, sha256, read-only) and link; returns the problems found."""
        self._fork_check()
        problems: list[str] = []
        for data_type, sources in sorted(self.installed().items()):
            for source, versions in sorted(sources.items()):
                for version in versions:
                    spec = ResourceSpec(data_type, source, version)
                    try:
                        index = self.index(spec)
                    except ResourceError as exc:
                        problems.append(f"{spec}: {exc}")
                        continue
                    problems += version_problems(self.place(spec), self.layout(spec), index, self.is_complete(spec))
        for data_type, links in sorted(self.linked().items()):
            for source, version in sorted(links.items()):
                spec = ResourceSpec(data_type, source, version)
                problems += link_problems(self.place(spec), self.manifest(spec)["link"])
        return problems


__all__ = ["InstallResult", "PostSetup", "ResourceManager"]
