"""What names a resource version and where it lives: :class:`ResourceSpec` (``data_type/source@version``)
and :class:`VersionPlace`, the small value a layout, an install and a verification work on."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from molmo_lerobot.resources.errors import ResourceError

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
#: how a version appears in the install dir: one link to the version dir, or a tree of per-file links
LINK_MODES = ("dir", "file")
#: our bookkeeping dir at the root of the cache and install dirs
META = ".molmo"


@dataclass(frozen=True)
class ResourceSpec:
    """One resource version, written ``data_type/source@version``."""

    data_type: str
    source: str
    version: str

    def __post_init__(self) -> None:
        for field, value in (("data_type", self.data_type), ("source", self.source), ("version", self.version)):
            if not _NAME.match(value or ""):
                raise ResourceError(f"invalid {field} {value!r}: use letters, digits, '.', '_' or '-'")

    @classmethod
    def parse(cls, text: str | ResourceSpec) -> ResourceSpec:
        if isinstance(text, ResourceSpec):
            return text
        m = re.fullmatch(r"([^/@]+)/([^/@]+)@([^/@]+)", text.strip())
        if not m:
            raise ResourceError(f"invalid resource {text!r}: expected DATA_TYPE/SOURCE@VERSION")
        return cls(*m.groups())

    @property
    def rel(self) -> str:
        return f"{self.data_type}/{self.source}/{self.version}"

    def __str__(self) -> str:
        return f"{self.data_type}/{self.source}@{self.version}"


@dataclass(frozen=True)
class VersionPlace:
    """Where one version lives: the cache and install roots (every write walks from one of them) and,
    below them, its version dir, bookkeeping dir and install link."""

    spec: ResourceSpec
    cache_dir: Path
    install_dir: Path | None

    @property
    def version_dir(self) -> Path:
        """``<cache>/<data_type>/<source>/<version>``: exactly the packed tree, read-only."""
        return self.cache_dir / self.spec.rel

    @property
    def meta_dir(self) -> Path:
        """``<cache>/.molmo/<data_type>/<source>/<version>``: manifest, index, flags, temporary dirs."""
        return self.cache_dir / META / self.spec.rel

    @property
    def install_root(self) -> Path:
        """The install dir; :class:`ResourceError` when none is configured."""
        if self.install_dir is None:
            raise ResourceError("no install dir configured")
        return self.install_dir

    @property
    def link_path(self) -> Path:
        """``<install>/<data_type>/<source>``: the version-free path that points at the version."""
        return self.install_root / self.spec.data_type / self.spec.source
