"""Fixtures for the resource manager tests: source trees and hand-crafted remote versions."""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import os
import tarfile
from pathlib import Path

import pytest
import zstandard


@pytest.fixture
def src_tree(tmp_path):
    """A small source tree: nested files, a binary file, an internal symlink."""
    root = tmp_path / "src"
    (root / "apple_01").mkdir(parents=True)
    (root / "apple_01" / "apple_01.xml").write_text("<mujoco model='apple'/>\n")
    (root / "apple_01" / "mesh.bin").write_bytes(os.urandom(3000))
    (root / "mug_02" / "parts").mkdir(parents=True)
    (root / "mug_02" / "mug_02.xml").write_text("<mujoco model='mug'/>\n")
    (root / "mug_02" / "parts" / "handle.bin").write_bytes(os.urandom(2000))
    (root / "mug_02" / "same.xml").symlink_to("mug_02.xml")
    (root / "README.txt").write_text("top level\n")
    return root


def _read_tree(root: Path) -> dict[str, bytes]:
    """``{rel: bytes}`` of every file reachable under ``root`` (following links)."""
    out = {}
    for dirpath, _dirs, files in os.walk(root, followlinks=True):
        for f in files:
            p = Path(dirpath, f)
            out[p.relative_to(root).as_posix()] = p.read_bytes()
    return out


@pytest.fixture
def craft_version(tmp_path):
    """Publish a hand-made archive (list of TarInfo/bytes) as ``objects/evil@1`` on a local remote.

    The manifest carries the archive's true sha256 so only the member checks can refuse it.
    """

    def make(members: list[tuple[tarfile.TarInfo, bytes | None]], index: dict | None = None, corrupt: bool = False):
        remote = tmp_path / "remote"
        vdir = remote / "objects" / "evil" / "1"
        (vdir / "archives").mkdir(parents=True)
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w", format=tarfile.PAX_FORMAT) as tar:
            for info, data in members:
                tar.addfile(info, io.BytesIO(data) if data is not None else None)
        blob = zstandard.ZstdCompressor().compress(buf.getvalue())
        name = "evil-1-00000.tar.zst"
        sha = hashlib.sha256(blob).hexdigest()
        if corrupt:
            blob = blob[:-20] + bytes(20)
        (vdir / "archives" / name).write_bytes(blob)
        manifest = {"format": 1, "data_type": "objects", "source": "evil", "version": "1", "link": "dir",
                    "uid_depth": 0, "archives": {name: {"size": len(blob), "sha256": sha, "n_files": 1}}}
        (vdir / "manifest.json").write_text(json.dumps(manifest))
        index = index or {name: {"ok.txt": [2, hashlib.sha256(b"ok").hexdigest()]}}
        (vdir / "index.json.gz").write_bytes(gzip.compress(json.dumps(index).encode()))
        return remote

    return make


@pytest.fixture
def craft_archives(tmp_path):
    """Publish ``{archive: [(TarInfo, bytes|None)]}`` as ``objects/evil@1`` with a matching manifest and index.

    Sizes, checksums and the index are true to the archives, so only the installer's own
    checks can refuse them. ``index``/``manifest`` edit the generated ones before writing.
    """

    def make(archives: dict[str, list], edit_index=None, edit_manifest=None, link: str = "dir") -> Path:
        remote = tmp_path / "remote"
        vdir = remote / "objects" / "evil" / "1"
        (vdir / "archives").mkdir(parents=True, exist_ok=True)
        entries, index = {}, {}
        for name, members in archives.items():
            buf = io.BytesIO()
            files = {}
            with tarfile.open(fileobj=buf, mode="w", format=tarfile.PAX_FORMAT) as tar:
                for info, data in members:
                    tar.addfile(info, io.BytesIO(data) if data is not None else None)
                    if info.issym():
                        files[info.name] = ["->", info.linkname]
                    elif info.isreg():
                        files[info.name] = [len(data), hashlib.sha256(data).hexdigest()]
            blob = zstandard.ZstdCompressor().compress(buf.getvalue())
            (vdir / "archives" / name).write_bytes(blob)
            entries[name] = {"size": len(blob), "sha256": hashlib.sha256(blob).hexdigest(), "n_files": len(files)}
            index[name] = files
        manifest = {"format": 1, "data_type": "objects", "source": "evil", "version": "1", "link": link,
                    "uid_depth": 0, "archives": entries}
        if edit_index:
            edit_index(index)
        if edit_manifest:
            edit_manifest(manifest)
        (vdir / "manifest.json").write_text(json.dumps(manifest))
        (vdir / "index.json.gz").write_bytes(gzip.compress(json.dumps(index).encode()))
        return remote

    return make


def _member(name: str, data: bytes | None = None, kind: bytes = tarfile.REGTYPE, linkname: str = ""):
    info = tarfile.TarInfo(name)
    info.type = kind
    info.linkname = linkname
    if data is not None:
        info.size = len(data)
    return info, data


@pytest.fixture
def read_tree():
    return _read_tree


@pytest.fixture
def tar_member():
    return _member
