"""Asset libraries: UID → MJCF + metadata document (MolmoSpaces' fields), and their plugin kind.

A plugin provides asset libraries as :class:`AssetLibraryType` s (hook ``molmo_asset_libraries``);
a run's catalog holds the libraries every type makes from the run's settings. Kinds here:

- :class:`BuiltinAssetLibrary` — the primitive objects of the procedural scenes;
- :class:`ObjectTableLibrary` — any in-memory table of objects (the articulated kitchen items);
- :class:`ResourceAssetLibrary` — a big library installed through the resource manager
  (``objects/<source>@<version>``: ``<uid>/<uid>.xml`` per object and one ``metadata.jsonl``),
  whose metadata is kept in LMDB; ``install`` fetches the object's archive and its grasps.

MolmoSpaces' formats (``thor``/``objaverse``, user libraries) are the ``molmospaces`` plugin's.
"""

from __future__ import annotations

import json
import os
import uuid
from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import lmdb
import zstandard

from molmo_lerobot import fileio
from molmo_lerobot.assets.grasps import BuiltinGraspLibrary, GraspLibrary
from molmo_lerobot.errors import MolmoError


class AssetError(MolmoError, LookupError):
    """An unknown UID or a malformed library; the message names the file, UID and field."""


@dataclass(frozen=True)
class UidLocation:
    """Where a UID lives: its library, the archive holding it (if packed) and its MJCF file.

    ``mjcf_path`` is ``None`` for generated MJCF (built-in objects): use ``library.mjcf(uid)``.
    """

    library: str
    archive: str | None
    mjcf_path: Path | None


class AssetLibrary(ABC):
    """A named collection of objects keyed by globally unique UIDs."""

    name: str
    #: whether :meth:`uids` is cheap enough to offer its UIDs as "did you mean" hints
    enumerable: bool = True

    @abstractmethod
    def uids(self) -> Iterator[str]: ...

    @abstractmethod
    def __contains__(self, uid: object) -> bool: ...

    @abstractmethod
    def metadata(self, uid: str) -> dict:
        """The metadata document of ``uid`` (raises :class:`AssetError` if unknown)."""

    @abstractmethod
    def locate(self, uid: str) -> UidLocation: ...

    def mjcf(self, uid: str) -> str:
        """The MJCF text of ``uid``."""
        path = self.install(uid).mjcf_path
        if path is None:
            raise AssetError(f"library {self.name!r}: UID {uid!r} has no MJCF")
        return Path(path).read_text()

    def install(self, uid: str) -> UidLocation:
        """Make ``uid``'s files (and grasps) available locally; returns its location."""
        return self.locate(uid)

    def grasp_library(self) -> GraspLibrary | None:
        """The grasp library that ships with this asset library, if any."""
        return None

    def fetch_grasps(self, uid: str) -> None:  # noqa: B027 - optional hook: does nothing unless overridden
        """Make ``uid``'s grasp files local before a grasp lookup (nothing to do unless they are packed)."""

    def _unknown(self, uid: str) -> AssetError:
        return AssetError(f"library {self.name!r} has no UID {uid!r}")


class ObjectTableLibrary(AssetLibrary):
    """An asset library over an in-memory table of objects (each with ``metadata()`` and ``mjcf()``)."""

    def __init__(self, name: str, objects: Mapping[str, Any], grasps: GraspLibrary) -> None:
        self.name = name
        self.objects = objects
        self._grasps = grasps

    def uids(self) -> Iterator[str]:
        return iter(sorted(self.objects))

    def __contains__(self, uid: object) -> bool:
        return uid in self.objects

    def _get(self, uid: str) -> Any:
        if uid not in self.objects:
            raise self._unknown(uid)
        return self.objects[uid]

    def metadata(self, uid: str) -> dict:
        return self._get(uid).metadata()

    def locate(self, uid: str) -> UidLocation:
        self._get(uid)
        return UidLocation(self.name, None, None)

    def mjcf(self, uid: str) -> str:
        return self._get(uid).mjcf()

    def grasp_library(self) -> GraspLibrary:
        return self._grasps


class BuiltinAssetLibrary(ObjectTableLibrary):
    """The built-in primitive objects and receptacles (``molmo_lerobot.assets.builtin``)."""

    def __init__(self) -> None:
        from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, BUILTIN_RECEPTACLES

        super().__init__("builtin", {**BUILTIN_OBJECTS, **BUILTIN_RECEPTACLES}, BuiltinGraspLibrary())


#: The built-in objects as a library type (the ``tabletop`` plugin provides it).
class MetadataStore:
    """UID → metadata document in LMDB (zstd JSON values, a completion marker); fork-safe."""

    COMPLETE = b"__complete__"

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._env: lmdb.Environment | None = None
        self._pid = -1
        self._dctx = zstandard.ZstdDecompressor()

    @classmethod
    def build(cls, path: str | os.PathLike, jsonl: str | os.PathLike) -> MetadataStore:
        """Load ``metadata.jsonl`` (one document with ``assetId`` per line) into a new store at ``path``."""
        jsonl = Path(jsonl)

        def docs() -> Iterator[tuple[str, Any]]:
            with open(jsonl) as fh:
                for lineno, line in enumerate(fh, 1):
                    if not line.strip():
                        continue
                    try:
                        doc = json.loads(line)
                        uid = doc["assetId"]
                    except (ValueError, KeyError, TypeError):
                        raise AssetError(f"{jsonl}:{lineno}: expected a JSON object with field 'assetId'") from None
                    yield uid, doc

        return cls.build_from(path, docs(), size_hint=jsonl.stat().st_size)

    @classmethod
    def build_from(cls, path: str | os.PathLike, docs, size_hint: int = 0, where: str = "") -> MetadataStore:
        """Write ``(uid, document)`` pairs into a new store at ``path`` (atomically)."""
        path = Path(path)
        tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
        cctx = zstandard.ZstdCompressor(level=3)
        env = lmdb.open(str(tmp), map_size=max(1 << 30, size_hint * 4), sync=False)
        try:
            with env.begin(write=True) as txn:
                for uid, doc in docs:
                    if not isinstance(uid, str) or not isinstance(doc, dict):
                        raise AssetError(f"{where or path}: entry {uid!r}: expected an object")
                    txn.put(uid.encode(), cctx.compress(json.dumps(doc).encode()))
                txn.put(cls.COMPLETE, b"1")
            env.sync(True)
        finally:
            env.close()
        try:
            fileio.replace(tmp, path, root=path.parent)
        except OSError:  # another process finished the same build first
            fileio.rmtree(tmp, root=path.parent, ignore_errors=True)
        return cls(path)

    @property
    def env(self) -> lmdb.Environment:
        if self._env is None or self._pid != os.getpid():
            from molmo_lerobot.resources.errors import ResourceError
            from molmo_lerobot.resources.index import open_readonly

            try:
                self._env = open_readonly(self.path, self.COMPLETE)
            except ResourceError as exc:
                raise AssetError(f"metadata store: {exc}; delete it to rebuild") from None
            self._pid, self._dctx = os.getpid(), zstandard.ZstdDecompressor()
        return self._env

    def exists(self) -> bool:
        return (self.path / "data.mdb").is_file()

    def get(self, uid: str) -> dict | None:
        with self.env.begin() as txn:
            raw = txn.get(uid.encode())
        return None if raw is None else json.loads(self._dctx.decompress(raw))

    def uids(self) -> Iterator[str]:
        with self.env.begin() as txn:
            keys = [k.decode() for k in txn.cursor().iternext(keys=True, values=False) if k != self.COMPLETE]
        return iter(keys)


class ResourceAssetLibrary(AssetLibrary):
    """A packed object library installed through a :class:`~molmo_lerobot.resources.ResourceManager`.

    ``objects`` names the object package (``objects/<source>@<version>``, packed with
    ``--uid-depth 0``: ``<uid>/<uid>.xml``, ``metadata.jsonl``); ``grasps`` optionally a grasp
    package (``grasps/<source>@<version>``, ``--uid-depth 1``: ``<robot>/<uid>.npz``).
    """

    METADATA = "metadata.jsonl"
    enumerable = False

    def __init__(self, manager, objects: str, grasps: str | None = None, name: str | None = None) -> None:
        from molmo_lerobot.resources.spec import ResourceSpec

        self.manager = manager
        self.objects, self.grasps = ResourceSpec.parse(objects), ResourceSpec.parse(grasps) if grasps else None
        self.name = name or self.objects.source
        self._store: MetadataStore | None = None

    def _meta(self) -> MetadataStore:
        if self._store is None:
            store = MetadataStore(self.manager.meta_dir(self.objects) / "metadata.lmdb")
            if not store.exists():
                fileio.make_dirs(store.path.parent, root=self.manager.cache_dir)  # LMDB writes in there
                store = MetadataStore.build(store.path, self.manager.ensure_path(self.objects, self.METADATA))
            self._store = store
        return self._store

    def uids(self) -> Iterator[str]:
        return self._meta().uids()

    def __contains__(self, uid: object) -> bool:
        return isinstance(uid, str) and bool(self.manager.index(self.objects).archives_for_uid(uid))

    def metadata(self, uid: str) -> dict:
        doc = self._meta().get(uid)
        if doc is None:
            raise self._unknown(uid)
        return doc

    def _mjcf_rel(self, uid: str) -> tuple[str, str]:
        index = self.manager.index(self.objects)
        for rel in (f"{uid}/{uid}.xml", f"{uid}/model.xml"):
            archive = index.archive_for_path(rel)
            if archive is not None:
                return archive, rel
        raise self._unknown(uid)

    def locate(self, uid: str) -> UidLocation:
        archive, rel = self._mjcf_rel(uid)
        return UidLocation(self.name, archive, self._root(self.objects) / rel)

    def install(self, uid: str) -> UidLocation:
        location = self.locate(uid)
        self.manager.ensure_uid(self.objects, uid)
        if self.grasps is not None and self.manager.index(self.grasps).archives_for_uid(uid):
            self.manager.ensure_uid(self.grasps, uid)
        return location

    def fetch_grasps(self, uid: str) -> None:
        """Grasp files of a packed library arrive with the object's archive."""
        if self.grasps is not None:
            self.install(uid)

    def _root(self, spec) -> Path:
        linked = self.manager.linked().get(spec.data_type, {}).get(spec.source)
        return self.manager.link_path(spec) if linked == spec.version else self.manager.version_dir(spec)

    def grasp_library(self) -> GraspLibrary | None:
        if self.grasps is None:
            return None
        return GraspLibrary(self._root(self.grasps), name=f"{self.name}-grasps")
