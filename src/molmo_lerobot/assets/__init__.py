"""Asset libraries (UID → MJCF + metadata), grasp libraries, their plugin kinds, and dataset ids."""

from molmo_lerobot.assets.catalog import AssetCatalog
from molmo_lerobot.assets.grasps import GraspError, GraspLibrary, GraspLibraryType
from molmo_lerobot.assets.libraries import (
    AssetError,
    AssetLibrary,
    AssetLibraryType,
    BuiltinAssetLibrary,
    ResourceAssetLibrary,
    UidLocation,
)

__all__ = [
    "AssetCatalog", "AssetError", "AssetLibrary", "AssetLibraryType", "BuiltinAssetLibrary", "GraspError",
    "GraspLibrary", "GraspLibraryType", "ResourceAssetLibrary", "UidLocation",
]
