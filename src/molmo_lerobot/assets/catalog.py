"""The asset catalog: every registered asset library and grasp library, in priority order.

``annotation(uid)`` unions the metadata of every library that knows ``uid`` (higher
priority wins per field); ``locate_uid`` / ``install_uid`` use the first library that holds
it. Grasp lookups try grasp libraries in priority order — a newly registered one goes first —
restricted to those mapped to a library holding the UID (or to any library): first those
made for the requested robot, then (MolmoSpaces' unified TCP convention makes grasps transfer)
those kept under another robot's name. The default catalog holds our built-in objects, the
articulated kitchen items, LIBERO's objects (``libero``) and MolmoSpaces' ``thor``/``objaverse`` libraries with their
``droid``/``droid_objaverse`` grasps; user libraries in MolmoSpaces' format go first.
"""

from __future__ import annotations

import difflib
import os
from functools import cache
from pathlib import Path

import numpy as np

from molmo_lerobot.assets.grasps import GraspError, GraspLibrary
from molmo_lerobot.assets.libraries import (
    AssetError,
    AssetLibrary,
    BuiltinAssetLibrary,
    ResourceAssetLibrary,
    UidLocation,
)
from molmo_lerobot.assets.user import ASSETS_INDEX, UserAssetLibrary, load_user_grasp_libraries

#: Object sources of MolmoSpaces that a user library may not be named after.
RESERVED_LIBRARY_NAMES = ("thor", "objaverse", "objathor_metadata")
#: A grasp-library robot name → our robots its grasps were made for (beyond the same name).
GRASP_ROBOT_NAMES = {"droid": ("franka_droid",)}


def _serves(library: GraspLibrary, robot: str) -> bool:
    """Whether ``library`` holds grasps made for ``robot`` (libraries keyed by robot always do)."""
    return library.robot is None or library.robot == robot or robot in GRASP_ROBOT_NAMES.get(library.robot, ())


class AssetCatalog:
    """Asset and grasp libraries in priority order (first registered last, user ones first)."""

    def __init__(self, with_builtin: bool = True) -> None:
        self.libraries: list[AssetLibrary] = []
        self.grasp_libraries: list[tuple[GraspLibrary, str | None]] = []  # (library, asset library name or None)
        if with_builtin:
            self.register_library(BuiltinAssetLibrary())

    # -- registration ------------------------------------------------------------------
    def register_library(self, library: AssetLibrary, first: bool = True) -> AssetLibrary:
        """Add an asset library (and the grasp library it ships with), ahead of the others."""
        if any(lib.name == library.name for lib in self.libraries):
            raise AssetError(f"an asset library named {library.name!r} is already registered")
        self.libraries.insert(0 if first else len(self.libraries), library)
        grasps = library.grasp_library()
        if grasps is not None:
            self.register_grasp_library(grasps, asset_library=library.name, first=first)
        return library

    def register_user_asset_library(self, name: str, path: str | os.PathLike) -> UserAssetLibrary:
        """Register a MolmoSpaces user asset library (``path/assets_index.json``), first in priority."""
        if not isinstance(name, str) or not name or "/" in name:
            raise AssetError(f"user asset library name {name!r} must be non-empty and contain no '/'")
        if name in RESERVED_LIBRARY_NAMES:
            raise AssetError(f"user asset library {name!r}: the name of a MolmoSpaces object source")
        if not (Path(path) / ASSETS_INDEX).is_file():
            raise AssetError(f"user asset library {name!r}: {Path(path) / ASSETS_INDEX}: file not found")
        return self.register_library(UserAssetLibrary(name, path))  # type: ignore[return-value]

    def register_user_grasp_library(self, name: str, path: str | os.PathLike,
                                    asset_library_name: str) -> list[GraspLibrary]:
        """Register a MolmoSpaces user grasp library as ``name/<robot>`` entries for one asset library."""
        self.library(asset_library_name)  # must already be registered
        libraries = load_user_grasp_libraries(name, path)
        taken = {g.name for g, _ in self.grasp_libraries}
        for lib in libraries:
            if lib.name in taken:
                raise GraspError(f"a grasp library named {lib.name!r} is already registered")
        for lib in libraries:
            self.register_grasp_library(lib, asset_library=asset_library_name)
        return libraries  # type: ignore[return-value]

    def ensure_user_asset_library(self, name: str, path: str | os.PathLike, field: str) -> None:
        """Register unless the same library is registered already (a run config, once per process)."""
        root = Path(path).expanduser().resolve()
        for lib in self.libraries:
            if lib.name == name and isinstance(lib, UserAssetLibrary) and lib.root == root:
                return
        try:
            self.register_user_asset_library(name, root)
        except AssetError as exc:
            raise AssetError(f"{field}: {exc}") from None

    def ensure_user_grasp_library(self, name: str, path: str | os.PathLike, asset_library: str, field: str) -> None:
        root = Path(path).expanduser().resolve()
        mine = [g for g, mapped in self.grasp_libraries if g.name.startswith(f"{name}/") and mapped == asset_library
                and Path(g.root) == root]
        if mine:
            return
        try:
            self.register_user_grasp_library(name, root, asset_library)
        except (AssetError, GraspError) as exc:
            raise type(exc)(f"{field}: {exc}") from None

    def register_grasp_library(self, library: GraspLibrary | str | os.PathLike, asset_library: str | None = None,
                               first: bool = True) -> GraspLibrary:
        """Add a grasp library; ``asset_library`` restricts it to that library's UIDs."""
        if not isinstance(library, GraspLibrary):
            root = Path(library)
            if not root.is_dir():
                raise GraspError(f"grasp library {root}: not a directory")
            library = GraspLibrary(root)
        entry = (library, asset_library)
        self.grasp_libraries.insert(0 if first else len(self.grasp_libraries), entry)
        return library

    def library(self, name: str) -> AssetLibrary:
        for lib in self.libraries:
            if lib.name == name:
                return lib
        raise AssetError(f"no asset library named {name!r} (registered: {', '.join(l.name for l in self.libraries)})")

    # -- lookups -----------------------------------------------------------------------
    def owners(self, uid: str) -> list[AssetLibrary]:
        return [lib for lib in self.libraries if uid in lib]

    def _first(self, uid: str) -> AssetLibrary:
        owners = self.owners(uid)
        if not owners:
            raise self._unknown(uid)
        return owners[0]

    def _unknown(self, uid: str) -> AssetError:
        known = [u for lib in self.libraries if getattr(lib, "enumerable", not isinstance(lib, ResourceAssetLibrary))
                 for u in lib.uids()]
        close = difflib.get_close_matches(uid, known, n=3)
        hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
        return AssetError(f"unknown asset UID {uid!r} in libraries {[l.name for l in self.libraries]}{hint}")

    def annotation(self, uid: str) -> dict:
        """The union of ``uid``'s metadata over every library (higher priority wins per field)."""
        owners = self.owners(uid)
        if not owners:
            raise self._unknown(uid)
        doc: dict = {}
        for lib in reversed(owners):
            doc.update(lib.metadata(uid))
        return doc

    def locate_uid(self, uid: str) -> UidLocation:
        return self._first(uid).locate(uid)

    def install_uid(self, uid: str) -> UidLocation:
        """Install ``uid``'s archive and its grasps (packed libraries); returns its location."""
        return self._first(uid).install(uid)

    def mjcf(self, uid: str) -> str:
        return self._first(uid).mjcf(uid)

    def _grasp_sources(self, uid: str, robot: str) -> list[GraspLibrary]:
        """Grasp libraries for ``uid``: made for ``robot`` first, then other robots', each in priority order."""
        owners = self.owners(uid)
        names = {lib.name for lib in owners}
        for lib in owners:
            if isinstance(lib, ResourceAssetLibrary) and lib.grasps is not None:
                lib.install(uid)  # grasp files of packed libraries arrive with the object's archive
        mapped = [g for g, owner in self.grasp_libraries if owner is None or owner in names]
        return [g for g in mapped if _serves(g, robot)] + [g for g in mapped if not _serves(g, robot)]

    def get_grasps(self, uid: str, robot: str = "franka", joint: str | None = None) -> np.ndarray:
        """Grasps ``(N, 4, 4)`` in ``uid``'s frame from the first grasp library that has them."""
        sources = self._grasp_sources(uid, robot)
        for lib in sources:
            got = lib.load(uid, robot, joint)
            if got is not None:
                return got
        what = f"{uid!r} joint {joint!r}" if joint else repr(uid)
        raise GraspError(f"no grasps for {what} and robot {robot!r} in grasp libraries {[g.name for g in sources]}")

    def count_grasps(self, uid: str, robot: str = "franka", joint: str | None = None) -> int:
        for lib in self._grasp_sources(uid, robot):
            n = lib.count(uid, robot, joint)
            if n is not None:
                return n
        return 0

    def grasp_joints(self, uid: str, robot: str = "franka") -> list[str]:
        """Joints of an articulated ``uid`` that have per-joint grasps (first library that has any)."""
        for lib in self._grasp_sources(uid, robot):
            joints = lib.joints(uid, robot)
            if joints:
                return joints
        return []


@cache
def default_catalog() -> AssetCatalog:
    """The process-wide catalog: built-in, articulated and MolmoSpaces objects; user libraries join at runtime."""
    from molmo_lerobot.assets.articulated import ArticulatedAssetLibrary
    from molmo_lerobot.assets.libero import LiberoAssetLibrary
    from molmo_lerobot.molmospaces.layout import OBJECT_LIBRARY_TO_GRASP_LIBRARIES
    from molmo_lerobot.molmospaces.libraries import MolmoSpacesGrasps, MolmoSpacesObjects

    catalog = AssetCatalog()
    catalog.register_library(ArticulatedAssetLibrary(), first=False)
    catalog.register_library(LiberoAssetLibrary(), first=False)
    for source, grasp_sources in OBJECT_LIBRARY_TO_GRASP_LIBRARIES.items():
        catalog.register_library(MolmoSpacesObjects(source), first=False)
        for grasps in grasp_sources:
            catalog.register_grasp_library(MolmoSpacesGrasps(grasps), asset_library=source, first=False)
    return catalog


def annotation(uid: str) -> dict:
    return default_catalog().annotation(uid)


def locate_uid(uid: str) -> UidLocation:
    return default_catalog().locate_uid(uid)


def install_uid(uid: str) -> UidLocation:
    return default_catalog().install_uid(uid)


def register_user_asset_library(name: str, path: str | os.PathLike) -> UserAssetLibrary:
    """MolmoSpaces' ``register_user_asset_library(name, path)`` on the process-wide catalog."""
    return default_catalog().register_user_asset_library(name, path)


def register_user_grasp_library(name: str, path: str | os.PathLike, asset_library_name: str) -> list[GraspLibrary]:
    """MolmoSpaces' ``register_user_grasp_library(name, path, asset_library_name)`` on the process-wide catalog."""
    return default_catalog().register_user_grasp_library(name, path, asset_library_name)


def register_grasp_library(root: str | os.PathLike | GraspLibrary, asset_library: str | None = None) -> GraspLibrary:
    return default_catalog().register_grasp_library(root, asset_library)
