"""Asset libraries (UID → MJCF + metadata), grasp libraries and dataset namespaces."""

from molmo_lerobot.assets.catalog import (
    AssetCatalog,
    annotation,
    default_catalog,
    install_uid,
    locate_uid,
    register_grasp_library,
    register_user_asset_library,
    register_user_grasp_library,
)
from molmo_lerobot.assets.grasps import GraspError, GraspLibrary, count_grasps, get_grasps
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
    "ResourceAssetLibrary", "UidLocation", "UserAssetLibrary", "UserGraspLibrary", "annotation", "count_grasps",
    "default_catalog", "get_grasps", "install_uid", "locate_uid", "register_grasp_library",
    "register_user_asset_library", "register_user_grasp_library",
]
