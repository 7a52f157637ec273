"""Asset libraries (UID → MJCF + metadata), grasp libraries and dataset namespaces."""

from molmo_lerobot.assets.catalog import AssetCatalog
from molmo_lerobot.assets.grasps import GraspError, GraspLibrary
from molmo_lerobot.assets.libraries import (
    AssetError,
    AssetLibrary,
    BuiltinAssetLibrary,
    ResourceAssetLibrary,
    UidLocation,
)
from molmo_lerobot.assets.user import UserAssetLibrary, UserGraspLibrary

__all__ = [
    "AssetCatalog", "AssetError", "AssetLibrary", "BuiltinAssetLibrary", "GraspError", "GraspLibrary",
    "ResourceAssetLibrary", "UidLocation", "UserAssetLibrary", "UserGraspLibrary",
]
