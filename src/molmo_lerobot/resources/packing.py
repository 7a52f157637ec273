"""Packing a tree into a remote as one new version in our layout (``molmo-resources pack``): archives of
about a given size that never split a UID, ``index.json.gz`` and ``manifest.json`` (format 1)."""

from __future__ import annotations

import gzip
import json
import os
import tempfile
from pathlib import Path, PurePosixPath

from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_open, atomic_write
from molmo_lerobot.resources.archive import pack_archive, tree_entries
from molmo_lerobot.resources.errors import ResourceError
from molmo_lerobot.resources.remotes import Remote, open_remote
from molmo_lerobot.resources.spec import LINK_MODES, ResourceSpec


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
