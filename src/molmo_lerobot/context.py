"""The run context: everything run-wide, built once per process from the resolved run config.

:meth:`RunContext.build` loads the plugins (with the run's ``plugins.prefer`` pins), resolves
the MolmoSpaces settings and composes the asset catalog from the asset and grasp library types
the plugins provide (the run's user libraries among them). The main process builds one per run
and hands it down; a worker, the run's policy server and the Gymnasium env rebuild theirs from
the config they receive (:meth:`RunContext.portable_config`).
No module keeps run state of its own.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from molmo_lerobot.assets.catalog import AssetCatalog
from molmo_lerobot.molmospaces.settings import MolmoSpacesSettings, resolve
from molmo_lerobot.plugins import Plugins

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.load import Benchmark
    from molmo_lerobot.sim.env import Timing
    from molmo_lerobot.sim.render_profile import RenderProfile


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

        Raises :class:`~molmo_lerobot.plugins.PluginError` for a bad ``plugins.prefer`` pin or a
        library type several plugins provide,
        :class:`~molmo_lerobot.molmospaces.settings.SettingsError`, ``AssetError`` or ``GraspError``
        for bad MolmoSpaces settings or user libraries; each message names the key.
        """
        cfg = _plain(config)
        plugins = Plugins()
        plugins.set_preferences((cfg.get("plugins") or {}).get("prefer"))
        settings = resolve(cfg)
        return cls(cfg, plugins, settings, build_catalog(plugins, settings))

    @property
    def timing(self) -> Timing:
        """The run's ``timing`` (defaults for the keys it leaves out)."""
        from molmo_lerobot.sim.env import Timing

        return Timing(**(self.config.get("timing") or {}))

    @property
    def render_profile(self) -> RenderProfile:
        """The run's render profile (``render_profile`` of the config, set by :meth:`for_benchmark`;
        else the default profile with this process's overrides)."""
        from molmo_lerobot.sim.render_profile import RenderProfile, resolve_profile

        record = self.config.get("render_profile")
        return RenderProfile.from_record(record) if record else resolve_profile(None)

    def for_benchmark(self, bench: Benchmark) -> RunContext:
        """This context with the render profile ``bench`` names (with this process's overrides), which
        workers rebuilding it from :meth:`portable_config` then use."""
        from molmo_lerobot.sim.render_profile import RenderProfileError, resolve_profile

        try:
            profile = resolve_profile(bench.metadata.render_profile if bench.metadata else None)
        except RenderProfileError as exc:
            raise RenderProfileError(f"{bench.path}: benchmark_metadata.json: {exc}") from None
        return dataclasses.replace(self, config={**self.config, "render_profile": profile.record()})

    def portable_config(self) -> dict[str, Any]:
        """The config with every data path absolute: what a worker rebuilds this context from."""
        return {**self.config, **self.settings.to_config()}


def _plain(config: Mapping[str, Any] | None) -> dict[str, Any]:
    from omegaconf import DictConfig, OmegaConf

    if isinstance(config, DictConfig):
        return OmegaConf.to_container(config, resolve=True)  # type: ignore[return-value]
    return copy.deepcopy(dict(config or {}))


def build_catalog(plugins: Plugins, settings: MolmoSpacesSettings) -> AssetCatalog:
    """The libraries of every asset and grasp library type ``plugins`` provide, made for ``settings``.

    A type name two plugins provide fails with :class:`~molmo_lerobot.plugins.PluginConflict`
    unless the run pins one (``plugins.prefer.asset_library.<name>=<plugin>``).
    """
    assets = [plugins.resolve("asset_library", name) for name in plugins.names("asset_library")]
    grasps = [plugins.resolve("grasp_library", name) for name in plugins.names("grasp_library")]
    return AssetCatalog.compose(assets, grasps, settings)
