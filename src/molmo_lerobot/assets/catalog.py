"""The asset catalog: every registered asset library and grasp library, in priority order.

``annotation(uid)`` unions the metadata of every library that knows ``uid`` (higher
priority wins per field); ``locate_uid`` / ``install_uid`` use the first library that holds
it. Grasp lookups try grasp libraries in priority order — a newly registered one goes first —
restricted to those mapped to a library holding the UID (or to any library). The built-in
object library and its grasps are always registered, last.
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
    DirectoryAssetLibrary,
    ResourceAssetLibrary,
    UidLocation,
)


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

    def register_directory(self, root: str | os.PathLike, name: str | None = None) -> DirectoryAssetLibrary:
        """Register a user library from a directory (see :class:`DirectoryAssetLibrary`)."""
        return self.register_library(DirectoryAssetLibrary(root, name))  # type: ignore[return-value]

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
        known = [u for lib in self.libraries if not isinstance(lib, ResourceAssetLibrary) for u in lib.uids()]
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

    def _grasp_sources(self, uid: str) -> list[GraspLibrary]:
        owners = self.owners(uid)
        names = {lib.name for lib in owners}
        for lib in owners:
            if isinstance(lib, ResourceAssetLibrary) and lib.grasps is not None:
                lib.install(uid)  # grasp files of packed libraries arrive with the object's archive
        return [g for g, mapped in self.grasp_libraries if mapped is None or mapped in names]

    def get_grasps(self, uid: str, robot: str = "franka", joint: str | None = None) -> np.ndarray:
        """Grasps ``(N, 4, 4)`` in ``uid``'s frame from the first grasp library that has them."""
        sources = self._grasp_sources(uid)
        for lib in sources:
            got = lib.load(uid, robot, joint)
            if got is not None:
                return got
        what = f"{uid!r} joint {joint!r}" if joint else repr(uid)
        raise GraspError(f"no grasps for {what} and robot {robot!r} in grasp libraries {[g.name for g in sources]}")

    def count_grasps(self, uid: str, robot: str = "franka", joint: str | None = None) -> int:
        for lib in self._grasp_sources(uid):
            n = lib.count(uid, robot, joint)
            if n is not None:
                return n
        return 0

    def grasp_joints(self, uid: str, robot: str = "franka") -> list[str]:
        """Joints of an articulated ``uid`` that have per-joint grasps (first library that has any)."""
        for lib in self._grasp_sources(uid):
            joints = lib.joints(uid, robot)
            if joints:
                return joints
        return []


@cache
def default_catalog() -> AssetCatalog:
    """The process-wide catalog (built-in and articulated objects); user libraries are added at runtime."""
    from molmo_lerobot.assets.articulated import ArticulatedAssetLibrary

    catalog = AssetCatalog()
    catalog.register_library(ArticulatedAssetLibrary(), first=False)
    return catalog


def annotation(uid: str) -> dict:
    return default_catalog().annotation(uid)


def locate_uid(uid: str) -> UidLocation:
    return default_catalog().locate_uid(uid)


def install_uid(uid: str) -> UidLocation:
    return default_catalog().install_uid(uid)


def register_user_library(root: str | os.PathLike, name: str | None = None) -> DirectoryAssetLibrary:
    return default_catalog().register_directory(root, name)


def register_grasp_library(root: str | os.PathLike | GraspLibrary, asset_library: str | None = None) -> GraspLibrary:
    return default_catalog().register_grasp_library(root, asset_library)
