"""One plugin manager, one discovery path: entry points in the group ``molmo_lerobot``.

Loading is guarded: a plugin whose import (or hook) fails is recorded with its error and
everything else keeps working. Only a run that asks for something that broken plugin
would have provided fails, with a message naming the plugin and its error.
"""

from __future__ import annotations

import difflib
import importlib.metadata as md
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import pluggy

from molmo_lerobot import hookspecs

ENTRY_POINT_GROUP = hookspecs.PROJECT

#: provider hook → plugin kind shown by ``molmo-plugins``
KIND_HOOKS = {
    "molmo_task_types": "task",
    "molmo_robots": "robot",
    "molmo_camera_systems": "camera",
    "molmo_scene_datasets": "scene",
    "molmo_policies": "policy",
    "molmo_experts": "expert",
    "molmo_config_dirs": "config",
    "molmo_episode_overrides": "override",
    "molmo_recorders": "recorder",
}


class PluginError(LookupError):
    """A requested plugin is unknown or failed to load. The message says which and why."""


@dataclass
class PluginRecord:
    """One entry point and what became of it."""

    name: str
    value: str
    distribution: str
    version: str
    status: str = "ok"  # "ok" or "error"
    error: str | None = None
    kinds: list[str] = field(default_factory=list)
    provides: list[str] = field(default_factory=list)
    module: Any = None


class Plugins:
    """The loaded plugin set and the registries built from it."""

    def __init__(self, entry_points: Iterable[md.EntryPoint] | None = None) -> None:
        self.pm = pluggy.PluginManager(hookspecs.PROJECT)
        self.pm.add_hookspecs(hookspecs)
        self.records: list[PluginRecord] = []
        eps = entry_points if entry_points is not None else md.entry_points(group=ENTRY_POINT_GROUP)
        for ep in sorted(eps, key=lambda e: e.name):
            self._load(ep)
        self._registries: dict[str, dict[str, Any]] = {}

    def _load(self, ep: md.EntryPoint) -> None:
        dist = getattr(ep, "dist", None)
        rec = PluginRecord(
            name=ep.name,
            value=ep.value,
            distribution=dist.name if dist else "?",
            version=dist.version if dist else "?",
        )
        self.records.append(rec)
        try:
            module = ep.load()
            self.pm.register(module, name=ep.name)
        except Exception as exc:  # a broken plugin must never take the run down
            rec.status, rec.error = "error", _one_line(exc)
            rec.traceback = traceback.format_exc()  # type: ignore[attr-defined]
            return
        rec.module = module
        for impl in self.pm.get_hookcallers(module) or []:
            kind = KIND_HOOKS.get(impl.name)
            if kind:
                rec.kinds.append(kind)

    def add(self, module: Any, name: str) -> None:
        """Register an in-process plugin (tests, notebooks) as if it came from an entry point."""
        rec = PluginRecord(name=name, value=repr(module), distribution="(in-process)", version="-")
        self.pm.register(module, name=name)
        rec.module = module
        rec.kinds = [KIND_HOOKS[h.name] for h in self.pm.get_hookcallers(module) or [] if h.name in KIND_HOOKS]
        self.records.append(rec)
        self._registries.clear()

    def broken(self) -> list[PluginRecord]:
        return [r for r in self.records if r.status != "ok"]

    def _collect(self, hook_name: str) -> dict[str, Any]:
        """Call a provider hook plugin by plugin, so one failing hook only marks its own plugin."""
        if hook_name in self._registries:
            return self._registries[hook_name]
        registry: dict[str, Any] = {}
        for rec in self.records:
            if rec.status != "ok" or rec.module is None:
                continue
            impl = getattr(rec.module, hook_name, None)
            if impl is None or hook_name not in [h.name for h in self.pm.get_hookcallers(rec.module) or []]:
                continue
            try:
                items = impl() or []
            except Exception as exc:
                rec.status, rec.error = "error", f"{hook_name}() failed: {_one_line(exc)}"
                continue
            for item in items:
                keys = [item] if isinstance(item, str) else [item.name, *getattr(item, "aliases", ())]
                if not isinstance(item, str):
                    rec.provides.append(f"{KIND_HOOKS[hook_name]}:{item.name}")
                for key in keys:
                    registry.setdefault(key, (item, rec))
        self._registries[hook_name] = registry
        return registry

    def _get(self, hook_name: str, name: str) -> Any:
        registry = self._collect(hook_name)
        if name in registry:
            return registry[name][0]
        kind = KIND_HOOKS[hook_name]
        primary = sorted({item.name for item, _ in registry.values()})
        msg = f"unknown {kind} {name!r}"
        close = difflib.get_close_matches(name, list(registry), n=3)
        if close:
            msg += f"; did you mean {', '.join(repr(c) for c in close)}?"
        msg += f" (available: {', '.join(primary) or 'none'})"
        suspects = [r for r in self.broken() if name in r.name or r.name in name]
        for r in suspects or self.broken():
            msg += f"\n  plugin {r.name!r} from {r.distribution} failed to load: {r.error}"
        raise PluginError(msg)

    # Registries -----------------------------------------------------------------------
    def task_type(self, name: str) -> Any:
        """Task type by name or alias (MolmoSpaces ``task_cls`` dotted paths are aliases)."""
        return self._get("molmo_task_types", name)

    def robot(self, name: str) -> Any:
        return self._get("molmo_robots", name)

    def camera_system(self, name: str) -> Any:
        return self._get("molmo_camera_systems", name)

    def scene_dataset(self, name: str) -> Any:
        return self._get("molmo_scene_datasets", name)

    def policy(self, name: str) -> Any:
        return self._get("molmo_policies", name)

    def expert(self, task_type: str) -> Any:
        """The scripted expert registered for a task type (by the task type's name)."""
        return self._get("molmo_experts", task_type)

    def names(self, kind: str) -> list[str]:
        hook = next(h for h, k in KIND_HOOKS.items() if k == kind)
        return sorted({item.name for item, _ in self._collect(hook).values()})

    def config_dirs(self) -> list[str]:
        dirs: list[str] = []
        for rec in self.records:
            if rec.status == "ok" and rec.module is not None and hasattr(rec.module, "molmo_config_dirs"):
                try:
                    dirs.extend(str(d) for d in rec.module.molmo_config_dirs() or [])
                except Exception as exc:
                    rec.status, rec.error = "error", f"molmo_config_dirs() failed: {_one_line(exc)}"
        return dirs

    def recorder_factories(self, config: dict[str, Any]) -> list[Any]:
        """Every ``molmo_recorders`` implementation's factories for this run config."""
        factories: list[Any] = []
        for rec in self.records:
            fn = getattr(rec.module, "molmo_recorders", None) if rec.status == "ok" else None
            if fn is not None:
                factories.extend(fn(config=config) or [])
        return factories

    def apply_episode_overrides(self, episode: Any, config: Any) -> Any:
        """Run every ``molmo_episode_overrides`` implementation in registration order."""
        for rec in self.records:
            fn: Callable | None = getattr(rec.module, "molmo_episode_overrides", None) if rec.status == "ok" else None
            if fn is None:
                continue
            new = fn(episode=episode, config=config)
            if new is not None:
                episode = new
        return episode


def _one_line(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}".strip()
    return text.splitlines()[0] if text else type(exc).__name__


@cache
def get_plugins() -> Plugins:
    """The process-wide plugin set (loaded once per process; workers load their own)."""
    return Plugins()
