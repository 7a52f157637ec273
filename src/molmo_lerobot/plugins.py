"""One plugin manager, one discovery path: entry points in the group ``molmo_lerobot``.

Built-ins and third-party plugins load the same way. Every hook is dispatched through
pluggy (``pm.hook.<name>.get_hookimpls()``, so ``specname``, ``tryfirst`` and ``trylast``
apply) one implementation at a time, so that a plugin whose import or hook fails is
marked broken with its error while everything else keeps working; only a run that needs
what the broken plugin would have provided fails, naming it. The project's own plugins
(:attr:`PluginRecord.builtin`) are never skipped as broken: their hooks' failures are raised
(:class:`BuiltinHookError`).

Every item a provider hook returns must be an instance of its kind's base class
(:data:`KIND_BASES`, checked once as the plugins are collected): a third-party plugin giving
anything else is marked broken naming the kind, the item and the class expected; a built-in one
raises. Past registration, callers use the base classes' members directly.

Two plugins that provide the same name (a robot ``franka``, a policy ``random``) are a
clash: ``molmo-plugins`` lists it, and resolving that name fails naming both providers
unless the run pins one (``plugins.prefer.<kind>.<name>=<plugin>``, see :meth:`Plugins.set_preferences`).

There is no process-wide plugin set: a run's :class:`~molmo_lerobot.context.RunContext` builds its
own :class:`Plugins` (each process of the run builds one, with the run's pins).
"""

from __future__ import annotations

import difflib
import functools
import importlib
import importlib.metadata as md
import sys
import traceback
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, overload

import pluggy

from molmo_lerobot import hookspecs
from molmo_lerobot.errors import MolmoError, RunError
from molmo_lerobot.hookspecs import ConfigError

if TYPE_CHECKING:
    from molmo_lerobot.assets.catalog import AssetLibraryType, GraspLibraryType
    from molmo_lerobot.benchmark.generators import BenchmarkGenerator
    from molmo_lerobot.benchmark.packs import BenchmarkDir
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.cameras.base import CameraSystem
    from molmo_lerobot.dataset_layout import DatasetLayout
    from molmo_lerobot.executor_types import ExecutorType
    from molmo_lerobot.policies.base import PolicyType
    from molmo_lerobot.recording import RecorderFactory
    from molmo_lerobot.robots.base import RobotType
    from molmo_lerobot.run_config import RunConfig
    from molmo_lerobot.sim.scenes import SceneDataset
    from molmo_lerobot.tasks.base import TaskType

    #: what :meth:`Plugins.resolve` gives for a kind not spelled as a literal
    type Provided = (TaskType | RobotType | CameraSystem | SceneDataset | AssetLibraryType | GraspLibraryType
                     | PolicyType | BenchmarkDir | ExecutorType | BenchmarkGenerator)

ENTRY_POINT_GROUP = hookspecs.PROJECT
#: the distribution whose entry points are the built-in plugins
PROJECT_DISTRIBUTION = "molmo-lerobot"

#: provider hook → plugin kind shown by ``molmo-plugins``
KIND_HOOKS = {
    "molmo_task_types": "task",
    "molmo_robots": "robot",
    "molmo_camera_systems": "camera",
    "molmo_scene_datasets": "scene",
    "molmo_asset_libraries": "asset_library",
    "molmo_grasp_libraries": "grasp_library",
    "molmo_policies": "policy",
    "molmo_experts": "expert",
    "molmo_benchmarks": "benchmark",
    "molmo_benchmark_kinds": "benchmark_kind",
    "molmo_executors": "executor",
    "molmo_generators": "generator",
    "molmo_config_dirs": "config",
    "molmo_episode_overrides": "override",
    "molmo_recorders": "recorder",
}
#: kinds whose items are looked up by name (``plugins.prefer.<kind>``) → their hook
PROVIDER_HOOKS = {kind: hook for hook, kind in KIND_HOOKS.items()
                  if kind in ("task", "robot", "camera", "scene", "asset_library", "grasp_library", "policy", "expert",
                              "benchmark", "benchmark_kind", "executor", "generator")}

#: provider kind → ``"module:Class"`` every item of that kind must be an instance of; imported when
#: first needed (:func:`base_class`), so this module imports none of them
KIND_BASES = {
    "task": "molmo_lerobot.tasks.base:TaskType",
    "robot": "molmo_lerobot.robots.base:RobotType",
    "camera": "molmo_lerobot.cameras.base:CameraSystem",
    "scene": "molmo_lerobot.sim.scenes:SceneDataset",
    "asset_library": "molmo_lerobot.assets.catalog:AssetLibraryType",
    "grasp_library": "molmo_lerobot.assets.catalog:GraspLibraryType",
    "policy": "molmo_lerobot.policies.base:PolicyType",
    "expert": "molmo_lerobot.policies.base:PolicyType",
    "benchmark": "molmo_lerobot.benchmark.packs:BenchmarkDir",
    "benchmark_kind": "molmo_lerobot.benchmark_kinds:BenchmarkKind",
    "executor": "molmo_lerobot.executor_types:ExecutorType",
    "generator": "molmo_lerobot.benchmark.generators:BenchmarkGenerator",
}


@functools.cache
def base_class(kind: str) -> type | None:
    """The class :data:`KIND_BASES` names for ``kind``, imported; ``None`` for a kind it does not list."""
    if kind not in KIND_BASES:
        return None
    module, _, name = KIND_BASES[kind].partition(":")
    return getattr(importlib.import_module(module), name)


#: provider pins, ``{kind: {name: plugin}}`` (the run's ``plugins.prefer``)
Pins = Mapping[str, Mapping[str, str]]


class PluginError(MolmoError, LookupError):
    """A requested plugin is unknown or failed to load. The message says which and why."""


class PluginConflict(PluginError):
    """Several plugins provide the requested name and the run pins none of them."""


class BuiltinHookError(RunError):
    """A hook of one of the project's own plugins failed: the caller's failure, never a plugin skipped
    as broken (a built-in recorder that fails would otherwise drop the run's recording silently)."""


@dataclass
class PluginRecord:
    """One entry point (or in-process plugin) and what became of it."""

    name: str
    value: str
    distribution: str
    version: str
    status: str = "ok"  # "ok" or "error"
    error: str | None = None
    kinds: list[str] = field(default_factory=list)
    provides: list[str] = field(default_factory=list)
    module: Any = None
    traceback: str | None = None
    pm_name: str = ""  # the name it is registered under in the pluggy manager

    @property
    def label(self) -> str:
        return f"{self.name!r} ({self.distribution} {self.version})"

    @property
    def builtin(self) -> bool:
        """Whether it is one of this project's own plugins (registered by ``molmo-lerobot``'s entry points)."""
        return self.distribution.replace("_", "-").lower() == PROJECT_DISTRIBUTION

    def matches(self, ref: str) -> bool:
        """Whether ``ref`` names this plugin: entry-point name, ``<distribution>:<name>`` or distribution."""
        return ref in (self.name, f"{self.distribution}:{self.name}", self.distribution)


class Plugins:
    """The loaded plugin set and the registries built from it."""

    def __init__(self, entry_points: Iterable[md.EntryPoint] | None = None) -> None:
        self.pm = pluggy.PluginManager(hookspecs.PROJECT)
        self.pm.add_hookspecs(hookspecs)
        self.records: list[PluginRecord] = []
        self.prefer: dict[str, dict[str, str]] = {}
        self._provided: dict[str, dict[str, list[Any]]] | None = None  # pm name → kind → items
        self._indices: dict[str, tuple[Any, dict]] = {}  # kind → (the _provided it was built from, index)
        eps = entry_points if entry_points is not None else md.entry_points(group=ENTRY_POINT_GROUP)
        for ep in sorted(eps, key=lambda e: (e.name, _dist_name(e))):
            self._load(ep)

    # Loading --------------------------------------------------------------------------
    def _load(self, ep: md.EntryPoint) -> None:
        dist = getattr(ep, "dist", None)
        rec = PluginRecord(name=ep.name, value=ep.value, distribution=_dist_name(ep),
                           version=dist.version if dist else "?")
        self.records.append(rec)
        try:
            module = ep.load()
        except BaseException as exc:  # even sys.exit() or KeyboardInterrupt at import
            rec.traceback = traceback.format_exc()
            self._break(rec, _one_line(exc))
            return
        self._register(module, rec)

    def _register(self, plugin: Any, rec: PluginRecord) -> None:
        taken = {r.pm_name for r in self.records if r is not rec}
        rec.pm_name = rec.name if rec.name not in taken else f"{rec.distribution}:{rec.name}"
        rec.module = plugin
        try:
            self.pm.register(plugin, name=rec.pm_name)
        except Exception as exc:  # a hookimpl whose arguments the spec does not have, a duplicate, …
            self._break(rec, _one_line(exc))
            return
        problems = []
        for caller in self.pm.get_hookcallers(plugin) or []:
            impls = [i for i in caller.get_hookimpls() if i.plugin is plugin]
            if not caller.has_spec() and not all(i.optionalhook for i in impls):
                problems.append(f"implements unknown hook {caller.name}() (not in molmo_lerobot.hookspecs)")
            elif any(i.hookwrapper or i.wrapper for i in impls):
                problems.append(f"wraps {caller.name}(); hook wrappers are not supported")
            elif caller.name in KIND_HOOKS:
                rec.kinds.append(KIND_HOOKS[caller.name])
        if problems:
            self.pm.unregister(plugin)
            self._break(rec, "; ".join(problems))
        self._provided = None

    def add(self, plugin: Any, name: str) -> None:
        """Register an in-process plugin (tests, notebooks) as if it came from an entry point."""
        rec = PluginRecord(name=name, value=repr(plugin), distribution="(in-process)", version="-")
        self.records.append(rec)
        self._register(plugin, rec)

    def broken(self) -> list[PluginRecord]:
        """Plugins that failed to load or in a provider hook (every provider hook is called first)."""
        self._collect()
        return [r for r in self.records if r.status != "ok"]

    def _break(self, rec: PluginRecord, error: str, *, warn: bool = False) -> None:
        rec.status, rec.error = "error", error
        self._provided = None
        if warn:
            print(f"molmo_lerobot: warning: plugin {rec.label} is broken and was skipped: {error}", file=sys.stderr)

    # Dispatch -------------------------------------------------------------------------
    def _impls(self, hook_name: str) -> Iterable[tuple[PluginRecord, Any]]:
        """``(plugin, hookimpl)`` of the working plugins, in pluggy's call order."""
        live = {r.pm_name: r for r in self.records}
        # get_hookimpls() lists in reverse call order: trylast first, tryfirst last.
        for impl in reversed(getattr(self.pm.hook, hook_name).get_hookimpls()):
            rec = live.get(impl.plugin_name)
            if rec is not None and rec.status == "ok":
                yield rec, impl

    def _invoke(self, rec: PluginRecord, hook_name: str, impl: Any, kwargs: dict[str, Any], *,
                run_time: bool) -> tuple[bool, Any]:
        """Call one implementation; a failure marks its plugin broken and gives ``(False, None)``.

        At run time (``run_time``) a ``ValueError`` is the plugin rejecting its arguments and
        propagates, and Ctrl-C stops the run; elsewhere anything, even ``sys.exit()``, is caught.
        A built-in plugin's failure is never caught: it raises :class:`BuiltinHookError`.
        """
        passthrough = (ValueError, KeyboardInterrupt) if run_time else ()
        try:
            return True, impl.function(*(kwargs[arg] for arg in impl.argnames))
        except passthrough:
            raise
        except BaseException as exc:  # a third-party plugin must never take the process down
            self._fail(rec, hook_name, exc, warn=run_time)
            return False, None

    def _fail(self, rec: PluginRecord, hook_name: str, exc: BaseException, *, warn: bool = False) -> None:
        """Mark a third-party plugin broken by its hook's failure; a built-in's failure is raised."""
        if rec.builtin:
            if not isinstance(exc, Exception):  # Ctrl-C, sys.exit()
                raise exc
            raise BuiltinHookError(f"{hook_name}() of the built-in plugin {rec.label} failed: "
                                   f"{_one_line(exc)}") from exc
        self._break(rec, f"{hook_name}() failed: {_one_line(exc)}", warn=warn)

    def _wrong_type(self, rec: PluginRecord, hook_name: str, kind: str, item: Any, expected: str) -> None:
        """A provider hook gave ``item``, which is not a ``expected``: a third-party plugin is marked
        broken, a built-in one raises :class:`BuiltinHookError`."""
        what = (f"{hook_name}() gave {kind} {item.name!r} as a {type(item).__module__}.{type(item).__qualname__}, "
                f"not a {expected.replace(':', '.')} (subclass it)")
        if rec.builtin:
            raise BuiltinHookError(f"the built-in plugin {rec.label}: {what}")
        self._break(rec, what)

    def _call(self, hook_name: str, *, run_time: bool = False, **kwargs: Any) -> Iterable[tuple[PluginRecord, Any]]:
        """``(plugin, result)`` of each implementation of ``hook_name`` that did not fail."""
        for rec, impl in self._impls(hook_name):
            ok, result = self._invoke(rec, hook_name, impl, kwargs, run_time=run_time)
            if ok:
                yield rec, result

    def _collect(self) -> dict[str, dict[str, list[Any]]]:
        """Every provider hook of every plugin, called once; a plugin failing one, or giving an item
        that is not of its kind's base class (:data:`KIND_BASES`), provides nothing."""
        if self._provided is not None:
            return self._provided
        provided: dict[str, dict[str, list[Any]]] = {}
        for kind, hook in PROVIDER_HOOKS.items():
            base = base_class(kind)
            for rec, items in self._call(hook):
                try:
                    items = list(items or [])
                    for item in items:
                        if not isinstance(getattr(item, "name", None), str):
                            raise TypeError(f"returned {type(item).__name__} without a string 'name'")
                except Exception as exc:
                    self._fail(rec, hook, exc)
                    continue
                wrong = next((item for item in items if base is not None and not isinstance(item, base)), None)
                if wrong is not None:
                    self._wrong_type(rec, hook, kind, wrong, KIND_BASES[kind])
                    continue
                provided.setdefault(rec.pm_name, {})[kind] = items
        ok = {r.pm_name: r for r in self.records if r.status == "ok"}
        self._provided = {name: kinds for name, kinds in provided.items() if name in ok}
        for rec in self.records:
            rec.provides = [f"{k}:{item.name}" for k, items in self._provided.get(rec.pm_name, {}).items()
                            for item in items]
        return self._provided

    def _index(self, kind: str) -> dict[str, list[tuple[Any, PluginRecord]]]:
        """``name or alias → [(item, plugin), …]``, one entry per providing plugin."""
        provided = self._collect()
        built_from, index = self._indices.get(kind, (None, {}))
        if built_from is provided:
            return index
        index = {}
        self._indices[kind] = (provided, index)
        for rec in self.records:
            for item in provided.get(rec.pm_name, {}).get(kind, []):
                for key in dict.fromkeys([item.name, *getattr(item, "aliases", ())]):
                    providers = index.setdefault(key, [])
                    if all(r is not rec for _, r in providers):
                        providers.append((item, rec))
        return index

    # Registries -----------------------------------------------------------------------
    # One overload per kind: ``resolve("robot", …)`` is a RobotType to the type checker.
    @overload
    def resolve(self, kind: Literal["task"], name: str, prefer: Pins | None = None) -> TaskType: ...
    @overload
    def resolve(self, kind: Literal["robot"], name: str, prefer: Pins | None = None) -> RobotType: ...
    @overload
    def resolve(self, kind: Literal["camera"], name: str, prefer: Pins | None = None) -> CameraSystem: ...
    @overload
    def resolve(self, kind: Literal["scene"], name: str, prefer: Pins | None = None) -> SceneDataset: ...
    @overload
    def resolve(self, kind: Literal["asset_library"], name: str,
                prefer: Pins | None = None) -> AssetLibraryType: ...
    @overload
    def resolve(self, kind: Literal["grasp_library"], name: str,
                prefer: Pins | None = None) -> GraspLibraryType: ...
    @overload
    def resolve(self, kind: Literal["policy", "expert"], name: str, prefer: Pins | None = None) -> PolicyType: ...
    @overload
    def resolve(self, kind: Literal["benchmark"], name: str, prefer: Pins | None = None) -> BenchmarkDir: ...
    @overload
    def resolve(self, kind: Literal["executor"], name: str, prefer: Pins | None = None) -> ExecutorType: ...
    @overload
    def resolve(self, kind: Literal["generator"], name: str, prefer: Pins | None = None) -> BenchmarkGenerator: ...
    @overload
    def resolve(self, kind: str, name: str, prefer: Pins | None = None) -> Provided: ...

    def resolve(self, kind: str, name: str, prefer: Pins | None = None) -> Provided:
        """The ``kind`` item called ``name`` (or an alias of it).

        A name several plugins provide resolves only if ``prefer`` (default: the pins set
        by :meth:`set_preferences`) names one of them, as ``{kind: {name: plugin}}``.
        """
        if kind not in PROVIDER_HOOKS:
            raise PluginError(f"unknown plugin kind {kind!r} (kinds: {', '.join(PROVIDER_HOOKS)})")
        index = self._index(kind)
        providers = index.get(name)
        if not providers:
            raise PluginError(self._unknown(kind, name, index))
        if len(providers) == 1:
            return providers[0][0]
        pins = (self.prefer if prefer is None else prefer).get(kind) or {}
        pin = pins.get(name) or next((pins[item.name] for item, _ in providers if item.name in pins), None)
        who = " and ".join(f"plugin {rec.label}" for _, rec in providers)
        if pin is None:
            raise PluginConflict(f"{kind} {name!r} is provided by {who}; choose one with "
                                 f"plugins.prefer.{kind}.{name}=<plugin>")
        chosen = [item for item, rec in providers if rec.matches(str(pin))]
        if len(chosen) != 1:
            raise PluginConflict(f"plugins.prefer.{kind}.{name}={pin!r} names {len(chosen)} of the "
                                 f"providers of {kind} {name!r} ({who}); give one plugin name")
        return chosen[0]

    def provider(self, kind: str, name: str) -> PluginRecord:
        """The plugin whose ``kind`` item :meth:`resolve` gives for ``name``."""
        item = self.resolve(kind, name)
        return next(rec for found, rec in self._index(kind)[name] if found is item)

    def set_preferences(self, prefer: Pins | None) -> None:
        """Pin providers for clashing names (``{kind: {name: plugin}}``, the run's ``plugins.prefer``).

        Replaces earlier pins; every pin is checked now (known kind, a plugin that provides
        the name), so a typo fails before any work with one line.
        """
        pins = {str(k): {str(n): str(p) for n, p in (v or {}).items()} for k, v in (prefer or {}).items()}
        for kind, names in pins.items():
            if kind not in PROVIDER_HOOKS:
                raise PluginError(f"plugins.prefer.{kind}: unknown kind (kinds: {', '.join(PROVIDER_HOOKS)})")
            index = self._index(kind)
            for name, pin in names.items():
                providers = index.get(name)
                if not providers:
                    raise PluginError(f"plugins.prefer.{kind}.{name}: " + self._unknown(kind, name, index))
                if not any(rec.matches(pin) for _, rec in providers):
                    who = ", ".join(rec.label for _, rec in providers)
                    raise PluginError(f"plugins.prefer.{kind}.{name}={pin!r}: no such provider of "
                                      f"{kind} {name!r} (providers: {who})")
        self.prefer = pins

    def clashes(self) -> dict[tuple[str, str], list[PluginRecord]]:
        """``(kind, name) → providers`` for every name more than one plugin provides."""
        return {(kind, name): [rec for _, rec in providers]
                for kind in PROVIDER_HOOKS for name, providers in sorted(self._index(kind).items())
                if len(providers) > 1}

    def _unknown(self, kind: str, name: str, index: dict[str, list]) -> str:
        primary = sorted({item.name for providers in index.values() for item, _ in providers})
        msg = f"unknown {kind} {name!r}"
        close = difflib.get_close_matches(name, list(index), n=3)
        if close:
            msg += f"; did you mean {', '.join(repr(c) for c in close)}?"
        msg += f" (available: {', '.join(primary) or 'none'})"
        suspects = [r for r in self.broken() if name in r.name or r.name in name]
        for r in suspects or self.broken():
            msg += f"\n  plugin {r.name!r} from {r.distribution} failed to load: {r.error}"
        return msg

    def task_type(self, name: str) -> TaskType:
        """Task type by name or alias (MolmoSpaces ``task_cls`` dotted paths are aliases)."""
        return self.resolve("task", name)

    def robot(self, name: str) -> RobotType:
        return self.resolve("robot", name)

    def camera_system(self, name: str) -> CameraSystem:
        return self.resolve("camera", name)

    def scene_dataset(self, name: str) -> SceneDataset:
        return self.resolve("scene", name)

    def policy(self, name: str) -> PolicyType:
        return self.resolve("policy", name)

    def expert(self, task_type: str) -> PolicyType:
        """The scripted expert registered for a task type (by the task type's name)."""
        return self.resolve("expert", task_type)

    def provided(self, kind: str) -> list[tuple[Any, PluginRecord]]:
        """``(item, plugin)`` for every ``kind`` item of the working plugins, in pluggy's call order (the
        order a ``firstresult`` hook would ask them in: ``tryfirst`` first, ``trylast`` last)."""
        provided = self._collect()
        return [(item, rec) for rec, _ in self._impls(PROVIDER_HOOKS[kind])
                for item in provided.get(rec.pm_name, {}).get(kind, [])]

    def names(self, kind: str) -> list[str]:
        return sorted({item.name for providers in self._index(kind).values() for item, _ in providers})

    # Run-time hooks -------------------------------------------------------------------
    def config_dirs(self) -> list[str]:
        """Hydra config directories every plugin contributes, in pluggy's call order."""
        dirs: list[str] = []
        for rec, result in self._call("molmo_config_dirs"):
            try:
                dirs.extend(str(d) for d in result or [])
            except Exception as exc:
                self._fail(rec, "molmo_config_dirs", exc)
        return dirs

    def recorder_factories(self, config: RunConfig,
                           dataset_layout: DatasetLayout | None = None) -> list[RecorderFactory]:
        """Every ``molmo_recorders`` implementation's factories for this run config (validated, frozen) and
        ``dataset_layout``: the :class:`~molmo_lerobot.dataset_layout.DatasetLayout` the run's benchmark kind
        records in, or None.

        A plugin that rejects the config (``ValueError``) fails the run with a
        :class:`ConfigError`; a third-party one that fails otherwise is marked broken and skipped
        with a warning, so a broken third-party recorder never breaks runs that do not use it; a
        built-in one's failure fails the run (:class:`BuiltinHookError`).
        """
        factories: list[RecorderFactory] = []
        try:
            for _, result in self._call("molmo_recorders", run_time=True, config=config,
                                        dataset_layout=dataset_layout):
                factories.extend(result or [])
        except ConfigError:
            raise
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        return factories

    def apply_episode_overrides(self, episode: EpisodeSpec, context: Any) -> EpisodeSpec:
        """Run every ``molmo_episode_overrides`` implementation in pluggy's call order, with the
        run's :class:`~molmo_lerobot.context.RunContext` and its config (the validated, frozen
        :class:`~molmo_lerobot.run_config.RunConfig`).

        Each sees the previous one's result. ``ValueError`` (an override that cannot apply
        to this episode) propagates, failing the episode; any other failure marks the plugin
        broken and skips it (with a warning), so a broken override never breaks every run.
        """
        for rec, impl in self._impls("molmo_episode_overrides"):
            kwargs = {"episode": episode, "config": context.config, "context": context}
            ok, new = self._invoke(rec, "molmo_episode_overrides", impl, kwargs, run_time=True)
            if ok and new is not None:
                episode = new
        return episode


def _dist_name(ep: md.EntryPoint) -> str:
    dist = getattr(ep, "dist", None)
    return dist.name if dist else "?"


def _one_line(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}" if str(exc).strip() else type(exc).__name__
    return text.strip().splitlines()[0]
