"""Asset libraries (UID → MJCF + metadata), grasp libraries, their plugin kinds, and dataset ids."""

from molmo_lerobot.assets.catalog import AssetCatalog, AssetLibraryType, GraspLibraryType
from molmo_lerobot.assets.grasps import GraspError, GraspLibrary
from molmo_lerobot.assets.libraries import (
    AssetError,
    AssetLibrary,
    BuiltinAssetLibrary,
    ResourceAssetLibrary,
    UidLocation,
)

__all__ = [
    "AssetCatalog", "AssetError", "AssetLibrary", "AssetLibraryType", "BuiltinAssetLibrary", "GraspError",
    "GraspLibrary", "GraspLibraryType", "ResourceAssetLibrary", "UidLocation",
]
