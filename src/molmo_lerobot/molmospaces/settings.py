"""The run settings for MolmoSpaces data, part of a run's :class:`~molmo_lerobot.context.RunContext`.

:func:`resolve` reads ``molmospaces.assets_dir`` (else ``$MLSPACES_ASSETS_DIR``, else our
install dir), ``molmospaces.house_variant``, ``molmospaces.physics_options``,
``scene_xml_paths``, ``asset_libraries`` and ``grasp_libraries`` from the run config and
resolves every path to an absolute one (so workers started elsewhere see the same files).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.paths import molmospaces_assets_dir


class SettingsError(MolmoError, ValueError):
    """A MolmoSpaces setting of the run config is invalid; the message names the key."""


@dataclass(frozen=True)
class MolmoSpacesSettings:
    """Resolved settings. Paths are absolute strings (picklable, comparable)."""

    assets_dir: str
    house_variant: str = "ceiling"
    physics_options: dict[str, Any] = field(default_factory=dict)
    scene_xml_paths: tuple[str, ...] = ()
    asset_libraries: dict[str, str] = field(default_factory=dict)
    grasp_libraries: dict[str, dict[str, str]] = field(default_factory=dict)
    cache_dir: str | None = None
    remote: str | None = None

    @property
    def assets(self) -> Path:
        return Path(self.assets_dir)

    def to_config(self) -> dict[str, Any]:
        """The run-config keys that reproduce these settings (what a worker receives)."""
        d = asdict(self)
        return {
            "molmospaces": {k: d[k] for k in ("assets_dir", "house_variant", "physics_options", "cache_dir", "remote")},
            "scene_xml_paths": list(self.scene_xml_paths),
            "asset_libraries": dict(self.asset_libraries),
            "grasp_libraries": {k: dict(v) for k, v in self.grasp_libraries.items()},
        }


def _abs(value: Any, key: str) -> str:
    if not isinstance(value, (str, os.PathLike)) or not str(value).strip():
        raise SettingsError(f"{key}: expected a path, got {value!r}")
    return str(Path(value).expanduser().absolute())


def _mapping(value: Any, key: str) -> Mapping:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise SettingsError(f"{key}: expected a mapping, got {type(value).__name__}")
    return value


def resolve(config: Mapping[str, Any] | None = None) -> MolmoSpacesSettings:
    """Settings from a run config (a plain mapping); missing keys take their defaults."""
    config = config or {}
    ms = _mapping(config.get("molmospaces"), "molmospaces")
    variant = ms.get("house_variant") or "ceiling"
    if variant not in ("ceiling", "base"):
        raise SettingsError(f"molmospaces.house_variant: expected 'ceiling' or 'base', got {variant!r}")
    xml_paths = config.get("scene_xml_paths") or []
    if isinstance(xml_paths, (str, os.PathLike)) or not isinstance(xml_paths, (list, tuple)):
        raise SettingsError(f"scene_xml_paths: expected a list of scene XML paths, got {xml_paths!r}")
    grasps: dict[str, dict[str, str]] = {}
    for name, entry in _mapping(config.get("grasp_libraries"), "grasp_libraries").items():
        if not isinstance(entry, Mapping) or "path" not in entry or "asset_library" not in entry:
            raise SettingsError(f"grasp_libraries.{name}: expected {{path: DIR, asset_library: NAME}}, got {entry!r}")
        grasps[str(name)] = {"path": _abs(entry["path"], f"grasp_libraries.{name}.path"),
                             "asset_library": str(entry["asset_library"])}
    return MolmoSpacesSettings(
        assets_dir=str(molmospaces_assets_dir(ms.get("assets_dir")).absolute()),
        house_variant=variant,
        physics_options=dict(_mapping(ms.get("physics_options"), "molmospaces.physics_options")),
        scene_xml_paths=tuple(_abs(p, f"scene_xml_paths[{i}]") for i, p in enumerate(xml_paths)),
        asset_libraries={str(k): _abs(v, f"asset_libraries.{k}")
                         for k, v in _mapping(config.get("asset_libraries"), "asset_libraries").items()},
        grasp_libraries=grasps,
        cache_dir=_abs(ms["cache_dir"], "molmospaces.cache_dir") if ms.get("cache_dir") else None,
        remote=str(ms["remote"]) if ms.get("remote") else None,
    )
