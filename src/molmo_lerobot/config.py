"""Hydra config: ``conf/`` plus every config directory plugins contribute.

Plugin config dirs join Hydra's search path through a Hydra ``SearchPathPlugin``
(``hydra_plugins.molmo_lerobot_searchpath``, found by Hydra's own plugin discovery), which calls
:func:`add_plugin_configs`; so ``molmo-eval`` (a Hydra app), :func:`compose` and
``molmo-eval --info searchpath`` all see them, and importing this module changes nothing. That is also
when the config nodes that are not files are stored in Hydra's ConfigStore: ``molmo_run_defaults``,
each executor's ``executor/<name>`` (its options model's defaults), and ``molmo_open_map``, a config node
for free-form maps (``horizons``, ``camera.overrides``, ``plugins.prefer``, a policy's ``cameras``):
placed with ``- /molmo_open_map@<key>`` in a defaults list, ``<key>.<new>=v`` works on the command line
without Hydra's ``+``. Config comes before any run, so these read a plugin set of their own (discovery
is the same everywhere).
"""

from __future__ import annotations

import difflib
import re
from pathlib import Path

from hydra import compose as hydra_compose
from hydra import initialize_config_dir
from hydra.core.config_search_path import ConfigSearchPath
from hydra.core.config_store import ConfigStore
from hydra.core.global_hydra import GlobalHydra
from hydra.errors import HydraException, OverrideParseException
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from molmo_lerobot.benchmark_kinds import benchmark_kind, benchmark_kinds
from molmo_lerobot.hookspecs import ConfigError
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import PluginError, Plugins
from molmo_lerobot.run_config import RunConfig

__all__ = ["ConfigError", "add_plugin_configs", "compose", "config_message", "given_keys", "primary_config_dir"]


#: the run config's keys that pick a file of ``conf/<group>/`` (or a plugin's config dir)
CONFIG_GROUPS = ("policy", "benchmark", "executor")


def primary_config_dir() -> Path:
    return data_path("conf").resolve()


def add_plugin_configs(search_path: ConfigSearchPath) -> None:
    """Append every ``molmo_config_dirs`` directory to ``search_path`` (that of our configs) and store the
    config nodes that are not files: ``molmo_open_map``, ``molmo_run_defaults``, each executor's
    ``executor/<name>`` and a default ``policy/<name>`` / ``benchmark/<name>`` for every registered policy
    and benchmark that no config dir configures."""
    store = ConfigStore.instance()
    open_map = OmegaConf.create({})
    OmegaConf.set_struct(open_map, False)  # keys may be added below it without `+`
    store.store(name="molmo_open_map", node=open_map, provider="molmo_lerobot")
    store.store(name="molmo_run_defaults", node=run_defaults(), provider="molmo_lerobot")
    seen = [primary_config_dir()]
    plugins = Plugins()
    for d in plugins.config_dirs():
        path = Path(d).resolve()
        if path not in seen:
            seen.append(path)
            search_path.append(provider="molmo-plugin", path=f"file://{path}")
    _default_policy_configs(plugins, seen)
    _default_benchmark_configs(plugins, seen)
    _executor_configs(plugins, seen)


def _default_policy_configs(plugins: Plugins, config_dirs: list[Path]) -> None:
    """``policy/<name>`` = ``{name: <name>}`` (Hydra's ConfigStore) for each registered policy no
    config dir has a ``policy/<name>.yaml`` for, so a plugin that ships no yaml is still
    ``policy=<name>``; its factory gets ``{"name": <name>}`` plus any ``+policy.<key>=`` given, validated by
    its options model (``PolicyType.options``) with the model's defaults filled in."""
    store = ConfigStore.instance()
    for name in plugins.names("policy"):
        if not any((d / "policy" / f"{name}.yaml").is_file() for d in config_dirs):
            store.store(group="policy", name=name, node={"name": name}, provider="molmo_lerobot")


def _default_benchmark_configs(plugins: Plugins, config_dirs: list[Path]) -> None:
    """``benchmark/<name>`` = its kind's options at their defaults (``{name: <name>, path: null}`` for episode
    files) for each benchmark of every benchmark kind (:mod:`molmo_lerobot.benchmark_kinds`) no config dir has a
    ``benchmark/<name>.yaml`` for: the shipped benchmarks, the env suites' and those plugins add are
    ``benchmark=<name>`` without a yaml each, their options settable as ``benchmark.<key>=``."""
    store = ConfigStore.instance()
    for kind in benchmark_kinds(plugins):
        for name in kind.benchmarks(plugins):
            configured = any((d / "benchmark" / f"{name}.yaml").is_file() for d in config_dirs)
            if not configured and benchmark_kind(plugins, name) is kind:
                store.store(group="benchmark", name=name, node=kind.config_node(name),
                            provider="molmo_lerobot")


def _executor_configs(plugins: Plugins, config_dirs: list[Path]) -> None:
    """``executor/<name>`` = the options model's defaults for each registered executor no config dir has an
    ``executor/<name>.yaml`` for: the model states the options once (``executor.<key>=`` overrides them);
    a name several plugins provide gets ``{name: <name>}``, and the run says which to pin."""
    store = ConfigStore.instance()
    for name in plugins.names("executor"):
        if not any((d / "executor" / f"{name}.yaml").is_file() for d in config_dirs):
            try:
                node = plugins.resolve("executor", name).defaults()
            except PluginError:
                node = {"name": name}
            store.store(group="executor", name=name, node=node, provider="molmo_lerobot")


def run_defaults() -> dict[str, object]:
    """``RunConfig``'s defaults, the one statement of them, as the ``molmo_run_defaults`` node
    ``conf/eval.yaml`` lists; the config groups (``policy``, ``benchmark``, ``executor``) are its own."""
    return {k: v for k, v in RunConfig().plain().items() if k not in CONFIG_GROUPS}


def given_keys(overrides: list[str]) -> set[str]:
    """The options a command line's ``overrides`` give, as dotted keys (what a resume does not take from
    the run): ``a.b=1``, ``+a.b=1``, ``~a.b`` give ``a.b``; a config group's choice (``policy=lerobot``)
    gives ``policy.name``, the rest of the group being options the command line did not give."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    keys = (o.key_or_group for o in OverridesParser.create().parse_overrides(overrides))
    return {f"{key}.name" if key in CONFIG_GROUPS else key for key in keys}


def compose(overrides: list[str], config_name: str = "eval") -> DictConfig:
    """Compose ``config_name`` with ``overrides`` (no Hydra app: nothing is written)."""
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(primary_config_dir()), version_base="1.3"):
            cfg = hydra_compose(config_name=config_name, overrides=overrides)
    except (HydraException, OmegaConfBaseException) as exc:
        raise ConfigError(config_message(exc)) from None
    finally:
        GlobalHydra.instance().clear()
    OmegaConf.set_struct(cfg, False)
    cfg.pop("hydra", None)
    return cfg


def config_message(exc: BaseException) -> str:
    """Hydra's message for a bad override or config: a did-you-mean for an unknown group
    option, one line for an unknown key of the run config's schema, otherwise Hydra's full
    text (with its ``+key=value`` hint and the cause); one line that says how to quote for an
    override its grammar cannot parse."""
    if isinstance(exc, OverrideParseException):
        return _override_message(exc.override, exc.message)
    text = str(exc).strip()
    unknown = re.fullmatch(r"Could not override '([^']+)'\.\nTo append to your config use (\S+)", text)
    if unknown and "is not in struct" in str(exc.__cause__):
        return _unknown_key_message(*unknown.groups()) or text
    missing = re.search(r"Could not find '([\w-]+)/([^']+)'", text)
    if missing:
        group, name = missing.groups()
        options = re.findall(r"^\t(\S+)$", text.split("Config search path")[0], flags=re.M)
        msg = f"unknown {group} {name!r}"
        close = difflib.get_close_matches(name, options, n=3)
        if close:
            msg += f"; did you mean {', '.join(map(repr, close))}?"
        msg += f" (available: {', '.join(options) or 'none'})"
        broken = Plugins().broken()  # the option may be one a broken plugin would have added
        for r in [r for r in broken if name in r.name or r.name in name] or broken:
            msg += f"\n  plugin {r.name!r} from {r.distribution} failed to load: {r.error}"
        return msg
    cause = exc.__cause__
    if isinstance(cause, OmegaConfBaseException) and str(cause).strip() and str(cause).strip() not in text:
        text += "\n" + str(cause).strip()
    return text or type(exc).__name__


def _unknown_key_message(key: str, append: str) -> str | None:
    """One line for ``key`` the run config's schema does not know; ``None`` inside a section
    a plugin's config defines (Hydra's ``+key=value`` hint is the answer there)."""
    from molmo_lerobot.run_config import section_keys

    section, _, name = key.rpartition(".")
    known = section_keys(section)
    if known is None:
        return None
    keys, closed = known
    close = difflib.get_close_matches(name, keys, n=3)
    hint = f"; did you mean {', '.join(repr('.'.join(filter(None, (section, c)))) for c in close)}?" if close else ""
    if closed:
        return f"Could not override {key!r}: {section} has no key {name!r}" + (hint or f" (known: {', '.join(keys)})")
    return f"Could not override {key!r}: no such key{hint} (a plugin's own key is added with {append})"


def _override_message(override: str, message: str) -> str:
    """One line for an override Hydra's grammar cannot parse; says how to quote a value that needs it."""
    lines = [line for line in message.splitlines() if not line.startswith("See https://")]
    detail = lines[0].split(": ", 1)[-1] if lines else "syntax error"
    if len(lines) > 1 and lines[0].startswith("LexerNoViableAltException"):  # Hydra points at the character
        at = len(lines[1]) - len(lines[1].lstrip()) - lines[0].rfind(override)
        detail = f"{override[at]!r} is not allowed there" if 0 <= at < len(override) else "a character is not allowed"
        key, sep, value = override.partition("=")
        if sep and len(key) < at < len(override) and not {"'", '"'} & set(value):
            return (f"cannot parse override {override!r}: {override[at]!r} is allowed only in a quoted value; "
                    f"quote it, e.g. molmo-eval '{key}=\"{value}\"'")
    return f"cannot parse override {override!r}: {detail} (grammar: https://hydra.cc/docs/advanced/override_grammar/basic)"
