"""MolmoSpaces' resource layout: file names, per-data-type behaviour, pinned versions, the
conversion of their metadata into our manifest and index, and :class:`MolmoSpacesLayout`, the
resource manager's layout for versions in their format.

What molmospaces-resources writes, and we read and write the same way:

- remote and cache version dir ``<data_type>/<source>/<version>/``: ``REMOTE_MANIFEST``
  (``{archive: size_mb}``), ``TRIES`` (gzip JSON ``{archive: path trie}``; a trie is nested
  dicts whose keys may hold several ``/``-joined components, empty dicts are leaves), the
  extracted tree, and an empty flag ``.<archive>_complete_extract`` per extracted archive;
- cache and install dir roots: ``LOCAL_MANIFEST`` (``{type: {source: [versions]}}`` in the
  cache, ``{type: {source: version}}`` in the install dir) and a ``.lock`` file lock each;
- install dir ``<data_type>/<source>``: one link to the version dir (their ``GLOBAL``), or a
  real dir of per-file links plus links to the two metadata files and an empty flag
  ``.<archive>_complete_links`` per linked archive (their ``PER_FILE``); their LMDB cache of
  the tries under ``.lmdb/<data_type>/<source>`` (dropped when the version changes).
"""

from __future__ import annotations

import gzip
import json
import os
import re
import shutil
from pathlib import Path

from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_open, atomic_write
from molmo_lerobot.resources.archive import extract_limit
from molmo_lerobot.resources.errors import RemoteNotFoundError, ResourceError
from molmo_lerobot.resources.layout import Layout
from molmo_lerobot.resources.manifests import (
    ARCHIVE_NAME,
    check_index,
    clean_rel,
    parse_manifest,
    read_json,
)
from molmo_lerobot.resources.records import Edit, update_record
from molmo_lerobot.resources.remotes import MOLMOSPACES, Remote
from molmo_lerobot.resources.spec import VersionPlace

REMOTE_MANIFEST = "mjthor_resource_file_to_size_mb.json"
TRIES = "mjthor_resources_combined_meta.json.gz"
LOCAL_MANIFEST = "mjthor_data_type_to_source_to_versions.json"
LOCK = ".lock"

#: MolmoSpaces' public bucket (their R2 bucket for MuJoCo data)
BUCKET_URL = "https://pub-3555e9bb2d304fab9c6c79819e48aa40.r2.dev"

#: Per data type: (link mode, eager); sources listed in ``EAGER_SOURCES`` are always eager.
BEHAVIOUR = {
    "robots": ("file", True),
    "scenes": ("file", False),
    "objects": ("dir", False),
    "grasps": ("dir", False),
    "test_data": ("dir", True),
    "benchmarks": ("dir", True),
    "textures": ("dir", True),
}
EAGER_SOURCES = {("objects", "thor"), ("objects", "objathor_metadata"), ("grasps", "droid"), ("grasps", "rum")}

#: The data MolmoSpaces' constants pin (scenes per dataset and split, object and grasp
#: libraries, robots), as ``{data_type: {source: version}}``.
VERSIONS: dict[str, dict[str, str]] = {
    "robots": {
        "rby1": "20251224", "rby1m": "20251224", "franka_droid": "20260127", "franka_cap": "20260213",
        "floating_rum": "20251110", "floating_robotiq": "20260208_retry4", "franka_fr3": "20260303",
        "i2rt_yam": "20260223", "g1": "20260802", "humans_rocketbox": "20260812",
    },
    "scenes": {
        "ithor": "20251217_with_occupancy", "refs": "20250923",
        "procthor-10k-train": "20251122_with_occupancy", "procthor-10k-val": "20251217_with_occupancy",
        "procthor-10k-test": "20251121_with_occupancy",
        "holodeck-objaverse-train": "20251217_with_occupancy", "holodeck-objaverse-val": "20251217_with_occupancy",
        "procthor-objaverse-train": "20251205_with_occupancy", "procthor-objaverse-val": "20251205_with_occupancy",
    },
    "objects": {"thor": "20251117", "objaverse": "20260131"},
    "grasps": {"droid": "20251116", "droid_objaverse": "20251218"},
}


def behaviour(data_type: str, source: str) -> tuple[str, bool]:
    """``(link mode, eager)`` MolmoSpaces uses for a source."""
    link, eager = BEHAVIOUR.get(data_type, ("dir", True))
    return link, eager or (data_type, source) in EAGER_SOURCES


def setup_archives(data_type: str, archives: list[str]) -> list[str]:
    """Archives MolmoSpaces extracts at setup for an on-demand source: every archive of a small
    scene dataset (under 10), else the scene archives whose names hold no number (shared bases)."""
    if data_type != "scenes":
        return []
    return list(archives) if len(archives) < 10 else [a for a in archives if not re.search(r"\d", a)]


def extract_flag(version_dir: Path, archive: str) -> Path:
    return version_dir / f".{archive.replace('/', '__')}_complete_extract"


def link_flag(link_dir: Path, archive: str) -> Path:
    return link_dir / f".{archive.replace('/', '__')}_complete_links"


def is_own_file(rel: str) -> bool:
    """Their bookkeeping inside a version dir (metadata and flags), not part of the data."""
    return rel in (REMOTE_MANIFEST, TRIES) or ("/" not in rel and rel.startswith(".")
                                                and rel.endswith("_complete_extract"))


def convert(data_type: str, source: str, version: str, sizes: object, tries: object,
            where: str) -> tuple[dict, dict[str, dict[str, list]]]:
    """Our manifest and index from their ``{archive: size_mb}`` manifest and ``{archive: trie}`` tries."""
    if not isinstance(sizes, dict) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and v >= 0 for v in sizes.values()):
        raise ResourceError(f"{where}: {REMOTE_MANIFEST} must map archive names to sizes in MB")
    for name in sizes:
        if not ARCHIVE_NAME.match(name) or not name.endswith(".tar.zst"):
            raise ResourceError(f"{where}: {REMOTE_MANIFEST}: archive name {name!r} is not a plain .tar.zst file name")
    if not isinstance(tries, dict):
        raise ResourceError(f"{where}: {TRIES} must map archive names to path tries")
    index = {archive: {path: [None, None] for path in trie_leaves(trie, f"{where}: {TRIES}: archive {archive}")}
             for archive, trie in tries.items()}
    for archive, paths in index.items():
        for path in paths:
            if is_own_file(path):  # an archive must not forge a completion flag or their metadata
                raise ResourceError(f"{where}: {TRIES}: archive {archive} holds {path!r}, a name MolmoSpaces "
                                    "keeps for its own bookkeeping")
    link, _ = behaviour(data_type, source)
    manifest = {"format": "molmospaces", "data_type": data_type, "source": source, "version": version,
                "link": link, "uid_depth": 0,
                "archives": {name: {"size": round(mb * 1e6), "size_mb": mb} for name, mb in sizes.items()}}
    return manifest, index


def trie_leaves(trie: object, where: str) -> list[str]:
    """Leaf paths of a (possibly compacted) path trie, walked without recursion."""
    if not isinstance(trie, dict):
        raise ResourceError(f"{where}: the trie must be a JSON object")
    leaves: list[str] = []
    stack: list[tuple[str, dict]] = [("", trie)]
    while stack:
        prefix, node = stack.pop()
        for key, child in node.items():
            path = f"{prefix}/{key}" if prefix else key
            if not isinstance(child, dict):
                raise ResourceError(f"{where}: node {path!r} is not a JSON object")
            if not clean_rel(path) or path.count("/") > 64:
                raise ResourceError(f"{where}: path {path!r} is not a clean relative path")
            if child:
                stack.append((path, child))
            else:
                leaves.append(path)
    return sorted(leaves)


def read_versions_file(path: Path) -> dict[str, dict[str, str]]:
    """A version table file ``{data_type: {source: version}}`` (their pinned-assets file format)."""
    data = read_json(Path(path), f"version table {path}")
    if not isinstance(data, dict) or not all(
            isinstance(s, dict) and all(isinstance(k, str) and isinstance(v, str) for k, v in s.items())
            for s in data.values()):
        raise ResourceError(f"version table {path}: must hold {{data_type: {{source: version}}}}")
    return data


def cache_dir() -> Path:
    """MolmoSpaces' cache dir: ``$MLSPACES_CACHE_DIR`` or theirs by default (so both tools share it)."""
    return Path(os.environ.get("MLSPACES_CACHE_DIR", "~/.cache/molmo-spaces-resources")).expanduser()


class MolmoSpacesLayout(Layout):
    """A version in molmospaces-resources' layout (see the module docstring), kept as their tool does.

    Their two metadata files stay beside ours (``<meta>/raw/``) and inside the version dir, an
    archive is done when their ``_complete_extract`` flag exists, and every change takes their
    ``.lock`` of the cache or install dir and updates their ``LOCAL_MANIFEST`` records.
    """

    format = MOLMOSPACES
    #: Their archives have no checksum or exact size: refuse one unpacking to more than this ratio.
    max_inflate_ratio = 64

    @classmethod
    def adopt(cls, place: VersionPlace) -> bool:
        vdir = place.version_dir
        if not ((vdir / REMOTE_MANIFEST).is_file() and (vdir / TRIES).is_file()):
            return False
        cls._convert(place, vdir, f"{place.spec}: cache {vdir}")
        return True

    @classmethod
    def fetch_meta(cls, place: VersionPlace, remote: Remote, tmp: Path) -> bool:
        spec = place.spec
        try:
            for name in (REMOTE_MANIFEST, TRIES):
                remote.download(f"{spec.rel}/{name}", tmp / name)
        except RemoteNotFoundError:
            return False
        cls._convert(place, tmp, f"{spec}: remote {remote.url} {spec.rel}")
        return True

    @classmethod
    def _convert(cls, place: VersionPlace, src: Path, where: str) -> None:
        """Our manifest and index from their two metadata files in ``src`` (kept beside them)."""
        spec, meta, root = place.spec, place.meta_dir, place.cache_dir
        sizes = read_json(src / REMOTE_MANIFEST, f"{where}/{REMOTE_MANIFEST}")
        tries = read_json(src / TRIES, f"{where}/{TRIES}")
        manifest, index = convert(spec.data_type, spec.source, spec.version, sizes, tries, where)
        manifest = parse_manifest(manifest, where)
        check_index(index, manifest["archives"], f"{where}/{TRIES}")
        for name in (REMOTE_MANIFEST, TRIES):
            if src != meta / "raw":
                with open(src / name, "rb") as fsrc, atomic_open(meta / "raw" / name, "wb", root=root) as dst:
                    shutil.copyfileobj(fsrc, dst)
        with atomic_open(meta / "index.json.gz", "wb", root=root) as raw, \
                gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as fh:
            fh.write(json.dumps(index).encode())
        atomic_write(meta / "manifest.json", json.dumps(manifest, indent=1, sort_keys=True), root=root)

    @classmethod
    def records(cls, root: Path) -> list[Path]:
        return [root / LOCAL_MANIFEST]

    @classmethod
    def own_link_file(cls, name: str) -> bool:
        return name.startswith(".") and name.endswith("_complete_links")

    def done(self) -> set[str]:
        vdir = self.place.version_dir
        return {a for a in self.manifest["archives"] if extract_flag(vdir, a).exists()}

    def mark_done(self, archive: str, entry: dict) -> None:
        atomic_write(extract_flag(self.place.version_dir, archive), "", root=self.place.cache_dir)

    def complete(self) -> bool:
        return set(self.manifest["archives"]) <= self.done()

    def check_download(self, part: Path, archive: str, entry: dict, files: dict[str, list],
                       inflated: int | None) -> int:
        """No checksum and sizes in MB only: bound the unpacked size instead."""
        return extract_limit(files) + (inflated if inflated is not None
                                       else self.max_inflate_ratio * part.stat().st_size)

    def own_file(self, rel: str) -> bool:
        return is_own_file(rel)

    def lock(self):
        return self.locks.hold(self.place.cache_dir / LOCK)

    def prepare(self) -> None:
        """Their metadata files inside the version dir, as molmospaces-resources keeps them."""
        root = self.place.cache_dir
        vdir = fileio.make_dirs(self.place.version_dir, root=root)
        for name in (REMOTE_MANIFEST, TRIES):
            if not (vdir / name).is_file():
                with open(self.place.meta_dir / "raw" / name, "rb") as src, \
                        atomic_open(vdir / name, "wb", root=root) as dst:
                    shutil.copyfileobj(src, dst)

    def record_cache(self, add: Edit) -> None:
        root = self.place.cache_dir
        update_record(root / LOCAL_MANIFEST, add, "list", root=root, indent=2)

    def link_lock(self):
        return self.locks.hold(self.place.install_root / LOCK)

    def link_files(self) -> list[str]:
        return [REMOTE_MANIFEST, TRIES]

    def flag_links(self, link_dir: Path, archives: list[str]) -> None:
        for archive in archives:
            atomic_write(link_flag(link_dir, archive), "", root=self.place.install_root)

    def record_link(self, point: Edit, previous: str | None) -> None:
        install, spec = self.place.install_root, self.place.spec
        if previous is not None and previous != spec.version:  # their cached tries index is per version
            fileio.rmtree(install / ".lmdb" / spec.data_type / spec.source, root=install, ignore_errors=True)
        update_record(install / LOCAL_MANIFEST, point, "str", root=install, indent=2)
