"""Hydra config composition: ``conf/`` plus every config directory contributed by plugins.

We compose with Hydra's compose API rather than ``@hydra.main`` so that the search path
can be extended with plugin directories discovered at run time, and so that Hydra does not
change the working directory or write its own output folders.
"""

from __future__ import annotations

import difflib
import re
from pathlib import Path

from hydra import compose as hydra_compose
from hydra import initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.errors import HydraException
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import get_plugins


class ConfigError(ValueError):
    """A command-line override or config file is invalid; the message says which."""


def compose(overrides: list[str], config_name: str = "eval") -> DictConfig:
    """Compose ``config_name`` with ``overrides``; plugin config dirs join the search path."""
    primary = data_path("conf")
    extra = [d for d in get_plugins().config_dirs() if Path(d).resolve() != primary.resolve()]
    searchpath = "hydra.searchpath=[" + ",".join(f"file://{d}" for d in extra) + "]"
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(primary), version_base="1.3"):
            cfg = hydra_compose(config_name=config_name, overrides=[*overrides, searchpath])
    except (HydraException, OmegaConfBaseException) as exc:
        raise ConfigError(_hydra_message(exc)) from None
    finally:
        GlobalHydra.instance().clear()
    OmegaConf.set_struct(cfg, False)
    cfg.pop("hydra", None)
    return cfg


def _hydra_message(exc: BaseException) -> str:
    """Hydra's message, shortened to what a user needs (with a did-you-mean for groups)."""
    text = str(exc).strip()
    missing = re.search(r"Could not find '([\w-]+)/([^']+)'", text)
    if missing:
        group, name = missing.groups()
        options = re.findall(r"^\t(\S+)$", text.split("Config search path")[0], flags=re.M)
        msg = f"unknown {group} {name!r}"
        close = difflib.get_close_matches(name, options, n=3)
        if close:
            msg += f"; did you mean {', '.join(map(repr, close))}?"
        return msg + f" (available: {', '.join(options) or 'none'})"
    return text.splitlines()[0] if text else type(exc).__name__
