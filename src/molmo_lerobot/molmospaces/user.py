"""User asset and grasp libraries in MolmoSpaces' own on-disk format, loaded unchanged.

A run's ``asset_libraries`` / ``grasp_libraries`` (its settings) become the ``user`` library
types' libraries, first in priority; :func:`register_user_asset_library` and
:func:`register_user_grasp_library` are MolmoSpaces' API of the same names, on a catalog.

Asset library (a directory with ``assets_index.json``)::

    {"<uid>": {"uid": "<uid>", "object_path": "<uid>/<uid>.xml",
               "metadata_path": "<uid>/<uid>.json", "metadata_npz_path": null}, ...}

``metadata_npz_path`` (optional) names an NPZ whose arrays join the metadata; an array key
``a/b`` lands at ``doc["a"]["b"]`` and may not overwrite a JSON field.

Grasp library (a directory with ``grasps_index.json``)::

    {"grasp_paths": {"<robot>": {"<uid>": "<uid>/<robot>/grasps.npz"}},
     "articulated_grasp_paths": {"<robot>": {"<uid>": {"<joint>": "<uid>/<robot>/joint_grasps_<joint>.npz"}}}}

Every NPZ holds ``transforms`` (N, 4, 4): TCP poses in the object's (articulated: the jointed
body's) frame. A grasp library registered as ``name`` becomes one library per robot,
``name/<robot>``. Paths are relative to the library directory; an entry that points outside
it or at a missing file is an error naming the index file and the entry.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from molmo_lerobot.assets.catalog import AssetCatalog
from molmo_lerobot.assets.grasps import GraspError, GraspLibrary
from molmo_lerobot.assets.libraries import AssetError, AssetLibrary, UidLocation
from molmo_lerobot.molmospaces.settings import MolmoSpacesSettings

ASSETS_INDEX = "assets_index.json"
GRASPS_INDEX = "grasps_index.json"
#: Object sources of MolmoSpaces that a user library may not be named after.
RESERVED_LIBRARY_NAMES = ("thor", "objaverse", "objathor_metadata")


def _read_index(path: Path, error: type[LookupError]) -> dict:
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise error(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{path}: cannot read ({exc})") from None
    except ValueError as exc:
        raise error(f"{path}: invalid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise error(f"{path}: expected a JSON object, got {type(data).__name__}")
    return data


def _inside(root: Path, rel: Any, index: Path, field: str, error: type[LookupError]) -> Path:
    """``root / rel``, checked to be a file inside ``root``."""
    if not isinstance(rel, str) or not rel:
        raise error(f"{index}: field {field}: expected a relative path, got {rel!r}")
    path = (root / rel).resolve()
    if not path.is_relative_to(root):
        raise error(f"{index}: field {field}: {rel!r} points outside the library ({root})")
    if not path.is_file():
        raise error(f"{index}: field {field}: {path} not found")
    return path


class UserAssetLibrary(AssetLibrary):
    """A MolmoSpaces user asset library (see the module docstring), checked when registered."""

    def __init__(self, name: str, root: str | os.PathLike) -> None:
        self.name = name
        self.root = Path(root).expanduser().resolve()
        self.index_path = self.root / ASSETS_INDEX
        index = _read_index(self.index_path, AssetError)
        self._entries: dict[str, dict[str, Path | None]] = {}
        for uid, entry in index.items():
            if not isinstance(entry, dict):
                raise AssetError(f"{self.index_path}: field {uid}: expected an object with object_path, metadata_path")
            paths: dict[str, Path | None] = {}
            for key in ("object_path", "metadata_path"):
                if key not in entry:
                    raise AssetError(f"{self.index_path}: field {uid}.{key}: missing")
                paths[key] = _inside(self.root, entry[key], self.index_path, f"{uid}.{key}", AssetError)
            npz = entry.get("metadata_npz_path")
            paths["metadata_npz_path"] = (
                None if npz is None
                else _inside(self.root, npz, self.index_path, f"{uid}.metadata_npz_path", AssetError))
            self._entries[uid] = paths
        self._docs: dict[str, dict] = {}

    def uids(self) -> Iterator[str]:
        return iter(sorted(self._entries))

    def __contains__(self, uid: object) -> bool:
        return uid in self._entries

    def metadata(self, uid: str) -> dict:
        if uid not in self._entries:
            raise self._unknown(uid)
        if uid not in self._docs:
            entry = self._entries[uid]
            doc = _read_index(entry["metadata_path"], AssetError)  # type: ignore[arg-type]
            if entry["metadata_npz_path"] is not None:
                where = f"{self.index_path}: field {uid}.metadata_npz_path"
                try:
                    with np.load(entry["metadata_npz_path"], allow_pickle=False) as npz:
                        arrays = {k: npz[k] for k in npz.files}
                except (OSError, ValueError) as exc:
                    raise AssetError(f"{where}: cannot read {entry['metadata_npz_path']} ({exc})") from None
                for key, value in arrays.items():
                    *parents, leaf = key.split("/")
                    d = doc
                    for part in parents:
                        d = d.setdefault(part, {})
                    if leaf in d:
                        raise AssetError(f"{where}: array {key!r} would overwrite a metadata field")
                    d[leaf] = value
            self._docs[uid] = doc
        return dict(self._docs[uid])

    def locate(self, uid: str) -> UidLocation:
        if uid not in self._entries:
            raise self._unknown(uid)
        return UidLocation(self.name, None, self._entries[uid]["object_path"])


class UserGraspLibrary(GraspLibrary):
    """The grasps of one robot from a MolmoSpaces user grasp library: ``<name>/<robot>``."""

    def __init__(self, name: str, root: Path, robot: str, rigid: dict[str, Path],
                 articulated: dict[str, dict[str, Path]]) -> None:
        super().__init__(root, name=f"{name}/{robot}")
        self.robot = robot
        self._rigid, self._articulated = rigid, articulated

    def path(self, uid: str, robot: str = "franka", joint: str | None = None) -> Path | None:
        return self._articulated.get(uid, {}).get(joint) if joint else self._rigid.get(uid)

    def joints(self, uid: str, robot: str = "franka") -> list[str]:
        return sorted(self._articulated.get(uid, {}))


def load_user_grasp_libraries(name: str, root: str | os.PathLike) -> list[UserGraspLibrary]:
    """One :class:`UserGraspLibrary` per robot of the grasp library at ``root``, checked."""
    root = Path(root).expanduser().resolve()
    index_path = root / GRASPS_INDEX
    index = _read_index(index_path, GraspError)
    rigid_all = index.get("grasp_paths", {})
    art_all = index.get("articulated_grasp_paths", {})
    for field, value in (("grasp_paths", rigid_all), ("articulated_grasp_paths", art_all)):
        if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
            raise GraspError(f"{index_path}: field {field}: expected {{robot: {{uid: ...}}}}")
    out = []
    for robot in sorted(set(rigid_all) | set(art_all)):
        rigid = {uid: _inside(root, rel, index_path, f"grasp_paths.{robot}.{uid}", GraspError)
                 for uid, rel in rigid_all.get(robot, {}).items()}
        articulated: dict[str, dict[str, Path]] = {}
        for uid, joints in art_all.get(robot, {}).items():
            if not isinstance(joints, dict):
                raise GraspError(f"{index_path}: field articulated_grasp_paths.{robot}.{uid}: expected {{joint: path}}")
            articulated[uid] = {j: _inside(root, rel, index_path, f"articulated_grasp_paths.{robot}.{uid}.{j}",
                                           GraspError) for j, rel in joints.items()}
        out.append(UserGraspLibrary(name, root, robot, rigid, articulated))
    return out


def user_asset_library(catalog: AssetCatalog, name: str, path: str | os.PathLike) -> UserAssetLibrary:
    """The user asset library at ``path`` (``path/assets_index.json``), checked to be new in ``catalog``."""
    if not isinstance(name, str) or not name or "/" in name:
        raise AssetError(f"user asset library name {name!r} must be non-empty and contain no '/'")
    if name in RESERVED_LIBRARY_NAMES:
        raise AssetError(f"user asset library {name!r}: the name of a MolmoSpaces object source")
    if not (Path(path) / ASSETS_INDEX).is_file():
        raise AssetError(f"user asset library {name!r}: {Path(path) / ASSETS_INDEX}: file not found")
    library = UserAssetLibrary(name, path)
    if any(lib.name == name for lib in catalog.libraries):
        raise AssetError(f"an asset library named {name!r} is already registered")
    return library


def user_grasp_libraries(catalog: AssetCatalog, name: str, path: str | os.PathLike,
                         asset_library: str) -> list[UserGraspLibrary]:
    """The user grasp library at ``path`` as ``name/<robot>`` libraries for ``asset_library`` of ``catalog``."""
    catalog.library(asset_library)  # must already be registered
    libraries = load_user_grasp_libraries(name, path)
    taken = {g.name for g, _ in catalog.grasp_libraries}
    for lib in libraries:
        if lib.name in taken:
            raise GraspError(f"a grasp library named {lib.name!r} is already registered")
    return libraries


def register_user_asset_library(catalog: AssetCatalog, name: str, path: str | os.PathLike) -> UserAssetLibrary:
    """Register a user asset library in ``catalog``, first in priority."""
    return catalog.register_library(user_asset_library(catalog, name, path))  # type: ignore[return-value]


def register_user_grasp_library(catalog: AssetCatalog, name: str, path: str | os.PathLike,
                                asset_library: str) -> list[UserGraspLibrary]:
    """Register a user grasp library in ``catalog`` for ``asset_library`` (registered already), first in priority."""
    libraries = user_grasp_libraries(catalog, name, path, asset_library)
    for lib in libraries:
        catalog.register_grasp_library(lib, asset_library=asset_library)
    return libraries


def run_asset_libraries(settings: MolmoSpacesSettings, catalog: AssetCatalog) -> list[AssetLibrary]:
    """The ``user`` asset library type: one library per ``asset_libraries`` entry of the run."""
    out: list[AssetLibrary] = []
    for name, path in settings.asset_libraries.items():
        try:
            out.append(user_asset_library(catalog, name, Path(path).resolve()))
        except AssetError as exc:
            raise AssetError(f"asset_libraries.{name}: {exc}") from None
    return out


def run_grasp_libraries(settings: MolmoSpacesSettings, catalog: AssetCatalog) -> list[tuple[GraspLibrary, str]]:
    """The ``user`` grasp library type: the libraries of every ``grasp_libraries`` entry of the run."""
    out: list[tuple[GraspLibrary, str]] = []
    for name, entry in settings.grasp_libraries.items():
        try:
            libraries = user_grasp_libraries(catalog, name, Path(entry["path"]).resolve(), entry["asset_library"])
        except (AssetError, GraspError) as exc:
            raise type(exc)(f"grasp_libraries.{name}: {exc}") from None
        out += [(lib, entry["asset_library"]) for lib in libraries]
    return out
