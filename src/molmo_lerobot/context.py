"""The run context: everything run-wide, built once per process from the validated run config.

:meth:`RunContext.build` takes the :class:`~molmo_lerobot.run_config.RunConfig` (a mapping is
validated into one first), loads the plugins (with the run's ``plugins.prefer`` pins), resolves
the MolmoSpaces settings and composes the asset catalog from the asset and grasp library types
the plugins provide (the run's user libraries among them). The main process builds one per run;
a worker, the run's policy server and the Gymnasium env build theirs with the same constructor
(a worker from :meth:`RunContext.portable_config` and the render profile's record).
:meth:`RunContext.for_benchmark` adds what the benchmark decides: its render profile and, unless
the run sets ``timing.sleep``, whether its episodes sleep. No module keeps run state of its own.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from molmo_lerobot.assets.catalog import AssetCatalog
from molmo_lerobot.molmospaces.settings import MolmoSpacesSettings, resolve
from molmo_lerobot.plugins import PluginError, Plugins
from molmo_lerobot.run_config import MolmoSpacesConfig, RunConfig, RunConfigError

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.load import Benchmark
    from molmo_lerobot.sim.env import Timing
    from molmo_lerobot.sim.render_profile import RenderProfile


@dataclass(frozen=True)
class RunContext:
    """One run's validated config, its plugins, MolmoSpaces settings and asset catalog."""

    config: RunConfig
    plugins: Plugins
    settings: MolmoSpacesSettings
    catalog: AssetCatalog
    #: the render profile's record (:meth:`for_benchmark`: the one the benchmark names); ``None``: the
    #: default profile with this process's overrides
    render_record: dict[str, Any] | None = None

    @classmethod
    def build(cls, config: RunConfig | Mapping[str, Any] | None = None,
              render_record: dict[str, Any] | None = None) -> RunContext:
        """A fresh context for ``config`` (a mapping or a composed ``DictConfig`` is validated first;
        ``None``: the defaults).

        Raises :class:`~molmo_lerobot.run_config.RunConfigError` listing every problem of the config,
        :class:`~molmo_lerobot.plugins.PluginError` for a bad ``plugins.prefer`` pin or a
        library type several plugins provide,
        :class:`~molmo_lerobot.molmospaces.settings.SettingsError`, ``AssetError`` or ``GraspError``
        for bad MolmoSpaces settings or user libraries; each message names the key.
        """
        config = RunConfig.of(config)
        plugins = Plugins()
        plugins.set_preferences(config.plugins.prefer)
        settings = resolve(config.model_dump())
        return cls(config, plugins, settings, build_catalog(plugins, settings), render_record)

    @property
    def timing(self) -> Timing:
        """The run's ``timing``, once ``timing.sleep`` is decided (given, or by :meth:`for_benchmark`)."""
        from molmo_lerobot.sim.env import Timing

        if self.config.timing.sleep is None:
            raise ValueError("timing.sleep is undecided: RunContext.for_benchmark decides it from the benchmark's "
                             "scene datasets")
        return Timing(**self.config.timing.model_dump())

    def timing_for(self, scene_dataset: str) -> Timing:
        """The timing an episode of ``scene_dataset`` runs with: the run's, with ``timing.sleep`` as decided,
        or where nothing decided it (a context used without :meth:`for_benchmark`: a script, a test, a
        worker job built by hand) as that scene dataset says (:attr:`SceneDataset.sleeps`)."""
        if self.config.timing.sleep is not None:
            return self.timing
        return self.with_sleep(self.plugins.scene_dataset(scene_dataset).sleeps).timing

    @property
    def render_profile(self) -> RenderProfile:
        """The run's render profile (:attr:`render_record`, else the default profile with this
        process's overrides)."""
        from molmo_lerobot.sim.render_profile import RenderProfile, resolve_profile

        record = self.render_record
        return RenderProfile.from_record(record) if record else resolve_profile(None)

    def for_benchmark(self, bench: Benchmark) -> RunContext:
        """This context as ``bench`` runs: with the render profile it names (with this process's overrides),
        whose record workers build their context with, and ``timing.sleep``, where the run leaves it
        unset, as its scene datasets say (:func:`scenes_sleep`), so that ``run.json`` records the value used."""
        from molmo_lerobot.sim.render_profile import RenderProfileError, resolve_profile

        try:
            profile = resolve_profile(bench.metadata.render_profile if bench.metadata else None)
        except RenderProfileError as exc:
            raise RenderProfileError(f"{bench.path}: benchmark_metadata.json: {exc}") from None
        run = dataclasses.replace(self, render_record=profile.record())
        return run if self.config.timing.sleep is not None else run.with_sleep(scenes_sleep(bench, self.plugins))

    def with_sleep(self, sleep: bool) -> RunContext:
        """This context with ``timing.sleep`` set to ``sleep``."""
        timing = self.config.timing.model_copy(update={"sleep": sleep})
        return dataclasses.replace(self, config=self.config.model_copy(update={"timing": timing}))

    def portable_config(self) -> RunConfig:
        """The config with every data path absolute: what a worker builds its context from."""
        portable = self.settings.to_config()
        return self.config.model_copy(update={**portable, "molmospaces": MolmoSpacesConfig(**portable["molmospaces"])})


def scenes_sleep(bench: Benchmark, plugins: Plugins) -> bool:
    """Whether ``bench``'s episodes sleep by their scene datasets (``SceneDataset.sleeps``: MolmoSpaces'
    yes, ours no). A dataset no plugin provides says nothing (its episodes cannot run and are recorded
    as errors); datasets that disagree are refused (:class:`RunConfigError`): ``timing.sleep`` decides."""
    says: dict[bool, list[str]] = {}
    for name in dict.fromkeys(episode.scene_dataset for episode in bench.episodes):
        try:
            scene = plugins.scene_dataset(name)
        except PluginError:
            continue
        says.setdefault(scene.sleeps, []).append(name)
    if len(says) > 1:
        raise RunConfigError([f"timing.sleep: benchmark {bench.path} mixes scene datasets whose episodes sleep "
                              f"({', '.join(says[True])}) with ones whose episodes do not "
                              f"({', '.join(says[False])}); set timing.sleep=true or timing.sleep=false"])
    return True in says


def build_catalog(plugins: Plugins, settings: MolmoSpacesSettings) -> AssetCatalog:
    """The libraries of every asset and grasp library type ``plugins`` provide, made for ``settings``.

    A type name two plugins provide fails with :class:`~molmo_lerobot.plugins.PluginConflict`
    unless the run pins one (``plugins.prefer.asset_library.<name>=<plugin>``).
    """
    assets = [plugins.resolve("asset_library", name) for name in plugins.names("asset_library")]
    grasps = [plugins.resolve("grasp_library", name) for name in plugins.names("grasp_library")]
    return AssetCatalog.compose(assets, grasps, settings)
