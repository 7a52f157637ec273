"""MolmoSpaces' built-in object and grasp libraries over the run's assets dir.

* ``thor``: every ``objects/thor/**/<uid>.xml`` (MolmoSpaces installs thor in full);
* ``objaverse``: ``objects/objaverse/**/<uid>.xml`` (installed per UID on demand); where the
  file is missing and ``molmospaces.cache_dir`` + ``molmospaces.remote`` are set,
  ``install_uid`` fetches it through our resource manager into the assets dir;
* metadata of both: MolmoSpaces' LMDB ``.lmdb/objathor_metadata/<version>`` (zstd pickles,
  read with an unpickler that admits plain data and numpy arrays only), else
  ``objects/objathor_metadata/objects_metadata.json.gz`` loaded once into our LMDB store;
* grasp libraries ``droid`` (thor) and ``droid_objaverse`` (objaverse):
  ``grasps/<lib>/<uid>/<uid>_grasps_filtered.npz``, per joint ``<joint>_grasps_filtered.npz``.

Each is a library type of the ``molmospaces`` plugin (:func:`asset_library_types`,
:func:`grasp_library_types`), made per run over its settings' assets dir.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import os
import pickle
import re
from collections.abc import Iterator
from functools import cache, partial
from pathlib import Path

import lmdb
import zstandard

from molmo_lerobot import fileio
from molmo_lerobot.assets.catalog import AssetCatalog, AssetLibraryType, GraspLibraryType
from molmo_lerobot.assets.grasps import GraspLibrary
from molmo_lerobot.assets.libraries import AssetError, AssetLibrary, MetadataStore, UidLocation
from molmo_lerobot.molmospaces import layout
from molmo_lerobot.molmospaces.settings import MolmoSpacesSettings
from molmo_lerobot.paths import home_dir

_OBJAVERSE_UID = re.compile(r"[0-9a-f]{32}")

#: The LMDB key MolmoSpaces writes last, when a metadata dump is complete.
LMDB_COMPLETE_KEY = "__LMDBMap__dump_complete__"


class _DataUnpickler(pickle.Unpickler):
    """Unpickles plain containers, strings, numbers and numpy arrays (protocols 2-5, in-band
    buffers only); refuses everything else."""

    ALLOWED = frozenset({
        ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
        ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar"),
        ("numpy.core.numeric", "_frombuffer"), ("numpy._core.numeric", "_frombuffer"),  # protocol 5
        ("numpy", "ndarray"), ("numpy", "dtype"), ("builtins", "set"), ("builtins", "frozenset"),
        ("collections", "OrderedDict"),
    })

    def find_class(self, module: str, name: str):
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"refusing to load {module}.{name} from object metadata")
        return super().find_class(module, name)

    @classmethod
    def loads(cls, data: bytes) -> object:
        """The unpickled object; any failure is one :class:`pickle.UnpicklingError` line."""
        try:
            return cls(io.BytesIO(data)).load()
        except pickle.UnpicklingError:
            raise
        except Exception as exc:  # allowed callables given bad arguments raise anything (TypeError, RuntimeError...)
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else "no message"
            raise pickle.UnpicklingError(f"{type(exc).__name__}: {first}") from None


class ObjathorMetadata:
    """UID → annotation document for thor and objaverse objects (see the module docstring)."""

    def __init__(self, assets: Path) -> None:
        self.assets = assets
        self._lmdb: lmdb.Environment | None = None
        self._pid = -1
        self._store: MetadataStore | None = None
        self._checked = False

    def _their_lmdb(self) -> Path | None:
        root = self.assets / ".lmdb" / "objathor_metadata"
        for version in sorted((p for p in root.glob("*") if (p / "data.mdb").is_file()), reverse=True):
            try:
                env = lmdb.open(str(version), readonly=True, lock=False, readahead=False)
            except lmdb.Error:
                continue
            with env.begin() as txn:
                done = txn.get(LMDB_COMPLETE_KEY.encode()) is not None
            env.close()
            if done:
                return version
        return None

    def _open(self) -> None:
        if self._checked and self._pid == os.getpid():
            return
        self._checked, self._pid, self._lmdb, self._store = True, os.getpid(), None, None
        theirs = self._their_lmdb()
        if theirs is not None:
            self._lmdb = lmdb.open(str(theirs), readonly=True, lock=False, readahead=False)
            return
        source = self.assets / "objects" / "objathor_metadata" / "objects_metadata.json.gz"
        if source.is_file():
            self._store = _store_for(source)

    def get(self, uid: str) -> dict | None:
        self._open()
        if self._lmdb is not None:
            with self._lmdb.begin() as txn:
                raw = txn.get(uid.encode())
            if raw is None:
                return None
            try:
                entry = _DataUnpickler.loads(zstandard.decompress(raw))
            except (pickle.UnpicklingError, zstandard.ZstdError) as exc:
                raise AssetError(f"{self.assets}/.lmdb/objathor_metadata: entry {uid!r} unreadable ({exc})") from None
            if not isinstance(entry, dict):
                raise AssetError(f"{self.assets}/.lmdb/objathor_metadata: entry {uid!r} is a "
                                 f"{type(entry).__name__}, not a mapping")
            return entry
        return self._store.get(uid) if self._store is not None else None


def _store_for(source: Path) -> MetadataStore:
    """Our LMDB copy of ``objects_metadata.json.gz`` (rebuilt when the file changes)."""
    stat = source.stat()
    key = hashlib.sha256(f"{source.resolve()}|{stat.st_size}|{stat.st_mtime_ns}".encode()).hexdigest()[:16]
    home = home_dir()
    store = MetadataStore(home / "molmospaces" / "metadata" / f"{key}.lmdb")
    if store.exists():
        return store
    try:
        with gzip.open(source, "rt") as fh:
            docs = json.load(fh)
    except (OSError, ValueError) as exc:
        raise AssetError(f"{source}: cannot read object metadata ({exc})") from None
    if not isinstance(docs, dict):
        raise AssetError(f"{source}: expected an object mapping UID to metadata")
    fileio.make_dirs(store.path.parent, root=home)
    return MetadataStore.build_from(store.path, docs.items(), where=str(source))


@cache
def metadata_for(assets: str) -> ObjathorMetadata:
    """The metadata of an assets dir, one per process (its LMDB environment is opened once)."""
    return ObjathorMetadata(Path(assets))


class MolmoSpacesObjects(AssetLibrary):
    """``thor`` or ``objaverse`` objects of the run's MolmoSpaces assets dir."""

    def __init__(self, name: str, settings: MolmoSpacesSettings) -> None:
        self.name = name
        self.enumerable = name == "thor"
        self.settings = settings
        self._index: dict[str, Path] | None = None

    @property
    def root(self) -> Path:
        return self.settings.assets / "objects" / self.name

    def _metadata(self, uid: str) -> dict | None:
        return metadata_for(self.settings.assets_dir).get(uid)

    def _xml_index(self) -> dict[str, Path]:
        """``<uid>.xml`` stem → file, for every MJCF under :attr:`root` (scanned once, again after an install)."""
        if self._index is None:
            self._index = {p.stem: p for p in sorted(self.root.rglob("*.xml"))} if self.root.is_dir() else {}
        return self._index

    def _file(self, uid: str) -> Path | None:
        direct = self.root / uid / f"{uid}.xml"
        if direct.is_file():
            return direct
        if self.name == "objaverse" and self._metadata(uid) is None:
            return None  # not an objaverse UID: never scan the (large) tree for it
        return self._xml_index().get(uid)

    def uids(self) -> Iterator[str]:
        return iter(sorted(self._xml_index()))

    def __contains__(self, uid: object) -> bool:
        """Installed here, or an objaverse UID (32 hex digits) its metadata knows, to be installed on demand."""
        if not isinstance(uid, str):
            return False
        if self._file(uid) is not None:
            return True
        return (self.name == "objaverse" and _OBJAVERSE_UID.fullmatch(uid) is not None
                and self._metadata(uid) is not None)

    def metadata(self, uid: str) -> dict:
        if uid not in self:
            raise self._unknown(uid)
        return self._metadata(uid) or {"assetId": uid}

    def locate(self, uid: str) -> UidLocation:
        path = self._file(uid)
        if path is None:
            if uid not in self:
                raise self._unknown(uid)
            path = self.root / uid / f"{uid}.xml"  # where install() puts it
        return UidLocation(self.name, None, path)

    def install(self, uid: str) -> UidLocation:
        path = self._file(uid)
        if path is not None:
            return UidLocation(self.name, None, path)
        settings = self.settings
        spec = f"objects/{self.name}@{layout.OBJECT_VERSIONS[self.name]}"
        if not (settings.cache_dir and settings.remote):
            raise AssetError(f"object {uid!r} is not installed under {self.root}; install it with "
                             f"`{layout.install_command(spec, settings.assets)} --uid {uid}` or set "
                             "molmospaces.cache_dir and molmospaces.remote to install objects as runs need them")
        from molmo_lerobot.resources import ResourceManager
        from molmo_lerobot.resources.errors import ResourceError

        try:
            manager = ResourceManager(settings.cache_dir, settings.assets, settings.remote, progress=False)
            manager.install(spec, on_demand=True)
            manager.ensure_uid(spec, uid)
            grasps = layout.OBJECT_LIBRARY_TO_GRASP_LIBRARIES[self.name][0]
            gspec = f"grasps/{grasps}@{layout.GRASP_VERSIONS[grasps]}"
            manager.install(gspec, on_demand=True)
            if manager.index(gspec).archives_for_uid(uid):
                manager.ensure_uid(gspec, uid)
        except ResourceError as exc:
            raise AssetError(f"object {uid!r}: install from {settings.remote} failed: {exc}") from None
        self._index = None
        path = self._file(uid)
        if path is None:
            raise AssetError(f"object {uid!r}: installed {spec} but {self.root} has no {uid}.xml")
        return UidLocation(self.name, None, path)


class MolmoSpacesGrasps(GraspLibrary):
    """``droid`` / ``droid_objaverse``: DROID-gripper grasps keyed by UID (see the module docstring)."""

    robot = "droid"

    def __init__(self, name: str, settings: MolmoSpacesSettings) -> None:
        super().__init__(settings.assets / "grasps" / name, name)

    def path(self, uid: str, robot: str = "franka", joint: str | None = None) -> Path | None:
        path = self.root / uid / f"{joint or uid}_grasps_filtered.npz"
        return path if path.is_file() else None

    def joints(self, uid: str, robot: str = "franka") -> list[str]:
        d = self.root / uid
        if not d.is_dir():
            return []
        names = (p.name.removesuffix("_grasps_filtered.npz") for p in d.glob("*_grasps_filtered.npz"))
        return sorted(n for n in names if n != uid)


#: Lookup priority of each object library and of its grasp libraries (thor before objaverse).
PRIORITY = {"thor": 100, "objaverse": 50}


def _objects(source: str, settings: MolmoSpacesSettings, catalog: AssetCatalog) -> list[AssetLibrary]:
    return [MolmoSpacesObjects(source, settings)]


def _grasps(name: str, source: str, settings: MolmoSpacesSettings,
            catalog: AssetCatalog) -> list[tuple[GraspLibrary, str | None]]:
    return [(MolmoSpacesGrasps(name, settings), source)]


def asset_library_types() -> list[AssetLibraryType]:
    """``thor`` and ``objaverse``."""
    return [AssetLibraryType(source, partial(_objects, source), PRIORITY[source])
            for source in layout.OBJECT_LIBRARY_TO_GRASP_LIBRARIES]


def grasp_library_types() -> list[GraspLibraryType]:
    """``droid`` for ``thor``, ``droid_objaverse`` for ``objaverse``."""
    return [GraspLibraryType(name, partial(_grasps, name, source), PRIORITY[source])
            for source, names in layout.OBJECT_LIBRARY_TO_GRASP_LIBRARIES.items() for name in names]
