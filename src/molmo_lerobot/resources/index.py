"""LMDB index of one resource version: path → archive, UID → archives, archive → file entries.

Values are zstd-compressed JSON; a ``__complete__`` key written in the last transaction
marks a finished dump, so a build killed half way is detected and redone. Handles are
reopened after ``fork`` (LMDB environments must not cross a fork).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import threading
import uuid
from collections.abc import Iterator, Mapping
from pathlib import Path, PurePosixPath

import lmdb
import zstandard

from molmo_lerobot import fileio
from molmo_lerobot.resources.errors import ResourceError

COMPLETE_KEY = b"__complete__"
_BATCH = 50_000
_MAX_KEY = 480


def uid_of(path: str, depth: int = 0) -> str | None:
    """The UID token of a packed path: its component at ``depth`` without suffixes."""
    parts = PurePosixPath(path).parts
    if len(parts) <= depth:
        return None
    return parts[depth].split(".", 1)[0] or None


def _key(prefix: bytes, text: str) -> bytes:
    raw = prefix + text.encode()
    return raw if len(raw) <= _MAX_KEY else prefix + b"#" + hashlib.sha1(text.encode()).hexdigest().encode()


class _Codec:
    """zstd contexts for one thread of one process: python-zstandard's must never be used by two
    threads at once (concurrent archive installs shared one and crashed the process)."""

    def __init__(self) -> None:
        self.pid = os.getpid()
        self.c = zstandard.ZstdCompressor(level=3)
        self.d = zstandard.ZstdDecompressor()

    def encode(self, obj) -> bytes:
        return self.c.compress(json.dumps(obj, separators=(",", ":")).encode())

    def decode(self, raw: bytes):
        return json.loads(self.d.decompress(raw))


class _ThreadCodec(threading.local):
    codec: _Codec | None = None


_codecs = _ThreadCodec()


def _get_codec() -> _Codec:
    """The calling thread's codec (a new one after a fork)."""
    codec = _codecs.codec
    if codec is None or codec.pid != os.getpid():
        codec = _codecs.codec = _Codec()
    return codec

_ENVS: dict[str, tuple[lmdb.Environment, tuple[int, int]]] = {}
_ENVS_PID = os.getpid()
_ENVS_LOCK = threading.Lock()


def open_readonly(path: str | os.PathLike, complete_key: bytes = COMPLETE_KEY) -> lmdb.Environment:
    """A process-wide read-only handle on a finished LMDB environment.

    LMDB forbids opening one environment twice per process, so handles are shared. After a
    fork the inherited handles are closed in the child (they are lock-free and read-only, so
    that leaves the parent untouched) and reopened; a rebuilt environment (new inode) is reopened.
    """
    global _ENVS_PID
    path = Path(path)
    with _ENVS_LOCK:
        if os.getpid() != _ENVS_PID:
            for env, _ in _ENVS.values():
                with contextlib.suppress(lmdb.Error):
                    env.close()
            _ENVS.clear()
            _ENVS_PID = os.getpid()
        try:
            st = os.stat(path / "data.mdb")
        except FileNotFoundError:
            raise ResourceError(f"LMDB {path} does not exist") from None
        ident, key = (st.st_dev, st.st_ino), str(path)
        cached = _ENVS.pop(key, None)
        if cached is not None:
            if cached[1] == ident:
                _ENVS[key] = cached
                return cached[0]
            cached[0].close()
        env = lmdb.open(str(path), readonly=True, lock=False, readahead=False, max_readers=512)
        with env.begin() as txn:
            complete = txn.get(complete_key) is not None
        if not complete:
            env.close()
            raise ResourceError(f"LMDB {path} is incomplete (a build was interrupted)")
        _ENVS[key] = (env, ident)
        return env


class PathIndex:
    """Read side of a built index directory (an LMDB environment)."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._env: lmdb.Environment | None = None
        self._pid = -1

    @property
    def env(self) -> lmdb.Environment:
        if self._env is None or self._pid != os.getpid():
            self._env = open_readonly(self.path)
            self._pid = os.getpid()
        return self._env

    def _get(self, key: bytes):
        with self.env.begin(buffers=False) as txn:
            raw = txn.get(key)
        return None if raw is None else _get_codec().decode(raw)

    def archive_for_path(self, path: str) -> str | None:
        return self._get(_key(b"p\0", path.strip("/")))

    def archives_for_uid(self, uid: str) -> list[str]:
        return self._get(_key(b"u\0", uid)) or []

    def files(self, archive: str) -> dict[str, list]:
        got = self._get(_key(b"a\0", archive))
        if got is None:
            raise ResourceError(f"index {self.path}: unknown archive {archive!r}")
        return got

    def meta(self) -> dict:
        return self._get(b"m\0meta") or {}

    @classmethod
    def build(cls, path: str | os.PathLike, entries: Mapping[str, Mapping[str, list]], uid_depth: int = 0,
              meta: dict | None = None) -> PathIndex:
        """Dump ``{archive: {path: entry}}`` into a fresh LMDB at ``path`` (replacing an incomplete one)."""
        path = Path(path)
        tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
        n_paths = sum(len(v) for v in entries.values())
        map_size = max(1 << 26, 512 * n_paths * 4 + sum(len(json.dumps(v)) for v in entries.values()) * 2)
        env = lmdb.open(str(tmp), map_size=map_size, subdir=True, sync=False, metasync=False)
        codec = _get_codec()
        try:
            uids: dict[str, list[str]] = {}
            for batch in _batches(_items(entries, uid_depth, uids), _BATCH):
                with env.begin(write=True) as txn:
                    for key, value in batch:
                        txn.put(key, codec.encode(value))
            with env.begin(write=True) as txn:
                for uid, archives in uids.items():
                    txn.put(_key(b"u\0", uid), codec.encode(archives))
                txn.put(b"m\0meta", codec.encode({"uid_depth": uid_depth, "archives": sorted(entries),
                                                  "n_paths": n_paths, **(meta or {})}))
                txn.put(COMPLETE_KEY, b"1")
            env.sync(True)
        finally:
            env.close()
        fileio.rmtree(path, root=path.parent)
        fileio.replace(tmp, path, root=path.parent)
        return cls(path)


def _items(entries: Mapping[str, Mapping[str, list]], uid_depth: int, uids: dict) -> Iterator[tuple[bytes, object]]:
    for archive, files in entries.items():
        yield _key(b"a\0", archive), dict(files)
        for rel in files:
            yield _key(b"p\0", rel), archive
            uid = uid_of(rel, uid_depth)
            if uid is not None:
                got = uids.setdefault(uid, [])
                if not got or got[-1] != archive:
                    got.append(archive)


def _batches(items, size):
    batch = []
    for item in items:
        batch.append(item)
        if len(batch) >= size:
            yield batch
            batch = []
    if batch:
        yield batch
