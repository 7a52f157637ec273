"""Resources: versioned read-only cache, version-free install dir, remotes, archives and index."""

from molmo_lerobot.resources.errors import (
    CorruptArchiveError,
    RemoteNotFoundError,
    ResourceError,
    StaleLockError,
    UnsafeArchiveError,
)
from molmo_lerobot.resources.manager import InstallResult, ResourceManager
from molmo_lerobot.resources.packing import pack
from molmo_lerobot.resources.remotes import HfRemote, HttpRemote, LocalRemote, Remote, open_remote
from molmo_lerobot.resources.spec import ResourceSpec

__all__ = [
    "CorruptArchiveError", "HfRemote", "HttpRemote", "InstallResult", "LocalRemote", "Remote", "RemoteNotFoundError",
    "ResourceError", "ResourceManager", "ResourceSpec", "StaleLockError", "UnsafeArchiveError", "open_remote", "pack",
]
