"""The ``libero`` asset library: the LIBERO objects (:mod:`molmo_lerobot.content.libero.objects`) with
the grasps computed from their collision geometry (:mod:`molmo_lerobot.content.libero.grasps`)."""

from __future__ import annotations

from molmo_lerobot.assets.catalog import AssetLibraryType
from molmo_lerobot.assets.libraries import ObjectTableLibrary
from molmo_lerobot.content.libero.grasps import LiberoGraspLibrary
from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS, object_metadata


class LiberoAssetLibrary(ObjectTableLibrary):
    """The ``libero`` asset library (module docstring), with its computed grasps."""

    def __init__(self) -> None:
        super().__init__("libero", LIBERO_OBJECTS, LiberoGraspLibrary())

    def metadata(self, uid: str) -> dict:
        return object_metadata(self._get(uid).uid)


#: The LIBERO objects as a library type (the ``libero_rooms`` plugin provides it).
LIBERO_LIBRARY_TYPE = AssetLibraryType("libero", lambda settings, catalog: [LiberoAssetLibrary()], priority=150)
