"""The asset catalog: every registered asset library and grasp library, in priority order.

``annotation(uid)`` unions the metadata of every library that knows ``uid`` (higher
priority wins per field); ``locate_uid`` / ``install_uid`` use the first library that holds
it. Grasp lookups try grasp libraries in priority order — a newly registered one goes first —
restricted to those mapped to a library holding the UID (or to any library): first those
made for the requested robot, then (MolmoSpaces' unified TCP convention makes grasps transfer)
those kept under another robot's name. A run's catalog
(:attr:`molmo_lerobot.context.RunContext.catalog`) is :meth:`AssetCatalog.compose` d from the
asset and grasp library types its plugins provide (:class:`AssetLibraryType`,
:class:`GraspLibraryType`, defined here beside the catalog their ``make`` receives); this module
names no library of its own.
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from molmo_lerobot.assets.grasps import GraspError, GraspLibrary
from molmo_lerobot.assets.libraries import AssetError, AssetLibrary, UidLocation

#: A grasp-library robot name → our robots its grasps were made for (beyond the same name).
GRASP_ROBOT_NAMES = {"droid": ("franka_droid",)}


def _serves(library: GraspLibrary, robot: str) -> bool:
    """Whether ``library`` holds grasps made for ``robot`` (libraries keyed by robot always do)."""
    return library.robot is None or library.robot == robot or robot in GRASP_ROBOT_NAMES.get(library.robot, ())


@dataclass(frozen=True)
class AssetLibraryType:
    """Asset libraries a plugin provides (``molmo_asset_libraries``), made per run.

    ``make(settings, catalog)`` returns this type's libraries for a run, from its
    :class:`~molmo_lerobot.molmospaces.settings.MolmoSpacesSettings`; ``catalog`` holds the
    libraries of lower priority, already registered (to check names against). Higher
    ``priority`` is looked up first: the run's user libraries 1000, built-in objects 300,
    articulated objects 200, MolmoSpaces' ``thor`` 100 and ``objaverse`` 50.
    """

    name: str
    make: Callable[[Any, AssetCatalog], Sequence[AssetLibrary]]
    priority: int = 0
    aliases: tuple[str, ...] = ()


@dataclass(frozen=True)
class GraspLibraryType:
    """Grasp libraries a plugin provides (``molmo_grasp_libraries``), made per run.

    ``make(settings, catalog)`` returns ``(grasp library, asset library name or None)`` pairs
    for a run: each serves the UIDs of that asset library (``None``: of any), which must be in
    ``catalog`` already (it holds every asset library of this priority or lower).
    ``priority`` orders lookups as :class:`~molmo_lerobot.assets.libraries.AssetLibraryType`'s
    does (a grasp library shipped with an asset library has that library's priority):
    MolmoSpaces' ``droid`` 100 (for ``thor``), ``droid_objaverse`` 50, user libraries 1000.
    """

    name: str
    make: Callable[[Any, AssetCatalog], Sequence[tuple[GraspLibrary, str | None]]]
    priority: int = 0
    aliases: tuple[str, ...] = ()


class AssetCatalog:
    """Asset and grasp libraries in priority order (the one registered last goes first)."""

    def __init__(self) -> None:
        self.libraries: list[AssetLibrary] = []
        self.grasp_libraries: list[tuple[GraspLibrary, str | None]] = []  # (library, asset library name or None)

    @classmethod
    def compose(cls, asset_types: Iterable[AssetLibraryType], grasp_types: Iterable[GraspLibraryType],
                settings: Any) -> AssetCatalog:
        """A run's catalog: the libraries of every type, made from the run's ``settings``.

        Types are made and registered from the lowest ``priority`` up (asset library types
        before grasp library types of equal priority, then by name), each library ahead of
        those before it: a higher priority is looked up first, and a grasp library type's
        libraries go ahead of those shipped with asset libraries of its priority.
        """
        steps: list[tuple[int, int, str, AssetLibraryType | GraspLibraryType]] = [
            *((t.priority, 0, t.name, t) for t in asset_types), *((t.priority, 1, t.name, t) for t in grasp_types)]
        steps.sort(key=lambda step: step[:3])
        catalog = cls()
        for *_, kind in steps:
            if isinstance(kind, GraspLibraryType):
                for grasps, asset_library in kind.make(settings, catalog):
                    catalog.register_grasp_library(grasps, asset_library=asset_library)
            else:
                for library in kind.make(settings, catalog):
                    catalog.register_library(library)
        return catalog

    # -- registration ------------------------------------------------------------------
    def register_library(self, library: AssetLibrary) -> AssetLibrary:
        """Add an asset library (and the grasp library it ships with), ahead of the others."""
        if any(lib.name == library.name for lib in self.libraries):
            raise AssetError(f"an asset library named {library.name!r} is already registered")
        self.libraries.insert(0, library)
        grasps = library.grasp_library()
        if grasps is not None:
            self.register_grasp_library(grasps, asset_library=library.name)
        return library

    def register_grasp_library(self, library: GraspLibrary | str | os.PathLike,
                               asset_library: str | None = None) -> GraspLibrary:
        """Add a grasp library; ``asset_library`` restricts it to that library's UIDs."""
        if not isinstance(library, GraspLibrary):
            root = Path(library)
            if not root.is_dir():
                raise GraspError(f"grasp library {root}: not a directory")
            library = GraspLibrary(root)
        self.grasp_libraries.insert(0, (library, asset_library))
        return library

    def library(self, name: str) -> AssetLibrary:
        for lib in self.libraries:
            if lib.name == name:
                return lib
        registered = ", ".join(lib.name for lib in self.libraries)
        raise AssetError(f"no asset library named {name!r} (registered: {registered})")

    # -- lookups -----------------------------------------------------------------------
    def owners(self, uid: str) -> list[AssetLibrary]:
        return [lib for lib in self.libraries if uid in lib]

    def _first(self, uid: str) -> AssetLibrary:
        owners = self.owners(uid)
        if not owners:
            raise self._unknown(uid)
        return owners[0]

    def _unknown(self, uid: str) -> AssetError:
        known = [u for lib in self.libraries if lib.enumerable for u in lib.uids()]
        close = difflib.get_close_matches(uid, known, n=3)
        hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
        return AssetError(f"unknown asset UID {uid!r} in libraries {[lib.name for lib in self.libraries]}{hint}")

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
            lib.fetch_grasps(uid)
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
