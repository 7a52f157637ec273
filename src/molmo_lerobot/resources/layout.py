"""Cache layouts: what a version of one manifest ``format`` keeps beside the manager's own bookkeeping.

The resource manager runs one install / lock / verify flow for every version and always keeps
its own records (``<cache>/.molmo/``: manifest, index, locks, ``complete``; the install dir's
``.molmo/installed.json``). A :class:`Layout`, chosen per version by its manifest's ``format``
(:data:`~molmo_lerobot.resources.formats.LAYOUTS`), supplies the rest: where the version's
metadata comes from (its remote files, or a version dir another tool filled), how an extracted
archive is checked and marked done, and what another tool sharing the cache expects to find (its
locks, flags and records). A layout works on a :class:`~molmo_lerobot.resources.spec.VersionPlace`
(where the version lives), the version's manifest and the dirs' :class:`~.locks.FileLocks`; it
never sees the manager. :class:`OwnLayout` is ours (``molmo-resources pack``);
:class:`~molmo_lerobot.resources.molmospaces.MolmoSpacesLayout` keeps molmospaces-resources'
layout, so either tool uses what the other installed.
"""

from __future__ import annotations

import contextlib
from abc import ABC, abstractmethod
from pathlib import Path
from typing import ClassVar

from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.resources.archive import extract_limit, verify_archive
from molmo_lerobot.resources.errors import RemoteNotFoundError, ResourceError
from molmo_lerobot.resources.locks import FileLocks
from molmo_lerobot.resources.manifests import check_index, parse_manifest, read_json
from molmo_lerobot.resources.records import Edit
from molmo_lerobot.resources.remotes import Remote
from molmo_lerobot.resources.spec import VersionPlace


class Layout(ABC):
    """One version's layout: where it lives (``place``), its ``manifest`` and the dirs' ``locks``.

    The defaults keep nothing beyond the manager's own records; a layout overrides what its
    format needs.
    """

    #: the manifest ``format`` this layout serves
    format: ClassVar[int | str]

    def __init__(self, place: VersionPlace, manifest: dict, locks: FileLocks) -> None:
        self.place, self.manifest, self.locks = place, manifest, locks

    # -- metadata, before the version's format is known --------------------------------
    @classmethod
    def adopt(cls, place: VersionPlace) -> bool:
        """Make our metadata (in ``place.meta_dir``) from a version dir another tool filled; ``False``: none there."""
        return False

    @classmethod
    @abstractmethod
    def fetch_meta(cls, place: VersionPlace, remote: Remote, tmp: Path) -> bool:
        """Fetch the version's metadata from ``remote`` into ``place.meta_dir`` (``manifest.json`` last: its
        presence means the metadata is complete); ``False``: the remote has no version in this layout."""

    @classmethod
    def records(cls, root: Path) -> list[Path]:
        """Files at the root of a cache or install dir where this layout's tool records versions."""
        return []

    @classmethod
    def own_link_file(cls, name: str) -> bool:
        """Bookkeeping this layout keeps at the top of a per-file link tree (not a link)."""
        return False

    # -- archives ----------------------------------------------------------------------
    @abstractmethod
    def done(self) -> set[str]:
        """Archives extracted into the version dir."""

    @abstractmethod
    def mark_done(self, archive: str, entry: dict) -> None:
        """Record ``archive`` as extracted into the version dir."""

    @abstractmethod
    def check_download(self, part: Path, archive: str, entry: dict, files: dict[str, list],
                       inflated: int | None) -> int:
        """Check a downloaded archive against its manifest ``entry``; returns the most bytes it may unpack to
        (``inflated``: its unpacked size, where the remote knows it)."""

    def complete(self) -> bool:
        """Whether the version is complete without our ``complete`` mark (another tool extracted it)."""
        return False

    def own_file(self, rel: str) -> bool:
        """Bookkeeping this layout keeps inside the version dir (not part of the data)."""
        return False

    # -- changes -----------------------------------------------------------------------
    def lock(self) -> contextlib.AbstractContextManager:
        """Held (inside our version lock) while the version's cache dir changes."""
        return contextlib.nullcontext()

    def prepare(self) -> None:  # noqa: B027 - optional hook: does nothing unless overridden
        """Ready the version dir before archives are extracted into it."""

    def record_cache(self, add: Edit) -> None:  # noqa: B027 - optional hook: does nothing unless overridden
        """Record the version as present in the cache (``add`` edits ``{type: {source: [versions]}}``)."""

    # -- links -------------------------------------------------------------------------
    def link_lock(self) -> contextlib.AbstractContextManager:
        """Held (inside our install lock) while the install dir's link changes."""
        return contextlib.nullcontext()

    def link_files(self) -> list[str]:
        """Files of the version dir linked in a per-file link tree beyond the data."""
        return []

    def flag_links(self, link_dir: Path, archives: list[str]) -> None:  # noqa: B027 - optional hook: does nothing unless overridden
        """Mark ``archives`` as linked in the per-file link tree ``link_dir``."""

    def record_link(self, point: Edit, previous: str | None) -> None:  # noqa: B027 - optional hook: does nothing unless overridden
        """Record the install dir's link (``point`` edits ``{type: {source: version}}``; ``previous``:
        the version linked before)."""


class OwnLayout(Layout):
    """Ours: ``manifest.json`` + ``index.json.gz`` on the remote, a sha256 per archive, done marks in
    ``<cache>/.molmo/<version>/done/<archive>.ok``."""

    format = 1

    @classmethod
    def fetch_meta(cls, place: VersionPlace, remote: Remote, tmp: Path) -> bool:
        spec, meta, root = place.spec, place.meta_dir, place.cache_dir
        try:
            remote.download(f"{spec.rel}/manifest.json", tmp / "manifest.json")
        except RemoteNotFoundError:
            return False
        remote.download(f"{spec.rel}/index.json.gz", tmp / "index.json.gz")
        where = f"{spec}: remote {remote.url} {spec.rel}/manifest.json"
        manifest = parse_manifest(read_json(tmp / "manifest.json", where), where)
        if (manifest["data_type"], manifest["source"], manifest["version"]) != (
                spec.data_type, spec.source, spec.version):
            raise ResourceError(f"{where} describes another resource")
        check_index(read_json(tmp / "index.json.gz", f"{spec}: remote index.json.gz"), manifest["archives"],
                    f"{spec}: remote {remote.url} {spec.rel}/index.json.gz")
        fileio.replace(tmp / "index.json.gz", meta / "index.json.gz", root=root)
        fileio.replace(tmp / "manifest.json", meta / "manifest.json", root=root)
        return True

    def done(self) -> set[str]:
        marks = self.place.meta_dir / "done"
        return {p.name[:-3] for p in marks.glob("*.ok")} if marks.is_dir() else set()

    def mark_done(self, archive: str, entry: dict) -> None:
        atomic_write(self.place.meta_dir / "done" / f"{archive}.ok", entry["sha256"], root=self.place.cache_dir)

    def check_download(self, part: Path, archive: str, entry: dict, files: dict[str, list],
                       inflated: int | None) -> int:
        verify_archive(part, archive, entry["size"], entry["sha256"])
        return extract_limit(files)
