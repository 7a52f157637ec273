"""The run context: everything run-wide, built once per process from the resolved run config.

:meth:`RunContext.build` loads the plugins (with the run's ``plugins.prefer`` pins), resolves
the MolmoSpaces settings and builds the asset catalog with the run's user libraries. The main
process builds one per run and hands it down; a worker, the run's policy server and the
Gymnasium env rebuild theirs from the config they receive (:meth:`RunContext.portable_config`).
No module keeps run state of its own.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot.assets.catalog import AssetCatalog
from molmo_lerobot.assets.grasps import GraspError
from molmo_lerobot.assets.libraries import AssetError
from molmo_lerobot.molmospaces.settings import MolmoSpacesSettings, resolve
from molmo_lerobot.plugins import Plugins

if TYPE_CHECKING:
    from molmo_lerobot.sim.env import Timing


@dataclass(frozen=True)
class RunContext:
    """One run's plugins, MolmoSpaces settings and asset catalog, and the config they came from."""

    config: dict[str, Any]
    plugins: Plugins
    settings: MolmoSpacesSettings
    catalog: AssetCatalog

    @classmethod
    def build(cls, config: Mapping[str, Any] | None = None) -> RunContext:
        """A fresh context for ``config`` (a plain mapping or an OmegaConf config; ``None``: defaults).

        Raises :class:`~molmo_lerobot.plugins.PluginError` for a bad ``plugins.prefer`` pin,
        :class:`~molmo_lerobot.molmospaces.settings.SettingsError`, ``AssetError`` or ``GraspError``
        for bad MolmoSpaces settings or user libraries; each message names the key.
        """
        cfg = _plain(config)
        plugins = Plugins()
        plugins.set_preferences((cfg.get("plugins") or {}).get("prefer"))
        settings = resolve(cfg)
        return cls(cfg, plugins, settings, build_catalog(settings))

    @property
    def timing(self) -> Timing:
        """The run's ``timing`` (defaults for the keys it leaves out)."""
        from molmo_lerobot.sim.env import Timing

        return Timing(**(self.config.get("timing") or {}))

    def portable_config(self) -> dict[str, Any]:
        """The config with every data path absolute: what a worker rebuilds this context from."""
        return {**self.config, **self.settings.to_config()}


def _plain(config: Mapping[str, Any] | None) -> dict[str, Any]:
    from omegaconf import DictConfig, OmegaConf

    if isinstance(config, DictConfig):
        return OmegaConf.to_container(config, resolve=True)  # type: ignore[return-value]
    return copy.deepcopy(dict(config or {}))


def build_catalog(settings: MolmoSpacesSettings) -> AssetCatalog:
    """Built-in and articulated objects, MolmoSpaces' ``thor``/``objaverse`` with their DROID grasps
    (over ``settings.assets_dir``), and ahead of them the user libraries ``settings`` names."""
    from molmo_lerobot.assets.articulated import ArticulatedAssetLibrary
    from molmo_lerobot.molmospaces.layout import OBJECT_LIBRARY_TO_GRASP_LIBRARIES
    from molmo_lerobot.molmospaces.libraries import MolmoSpacesGrasps, MolmoSpacesObjects

    catalog = AssetCatalog()
    catalog.register_library(ArticulatedAssetLibrary(), first=False)
    for source, grasp_sources in OBJECT_LIBRARY_TO_GRASP_LIBRARIES.items():
        catalog.register_library(MolmoSpacesObjects(source, settings), first=False)
        for grasps in grasp_sources:
            catalog.register_grasp_library(MolmoSpacesGrasps(grasps, settings), asset_library=source, first=False)
    for name, path in settings.asset_libraries.items():
        try:
            catalog.register_user_asset_library(name, Path(path).resolve())
        except AssetError as exc:
            raise AssetError(f"asset_libraries.{name}: {exc}") from None
    for name, entry in settings.grasp_libraries.items():
        try:
            catalog.register_user_grasp_library(name, Path(entry["path"]).resolve(), entry["asset_library"])
        except (AssetError, GraspError) as exc:
            raise type(exc)(f"grasp_libraries.{name}: {exc}") from None
    return catalog
