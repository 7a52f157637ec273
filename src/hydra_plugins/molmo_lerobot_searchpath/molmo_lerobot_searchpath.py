"""Adds the molmo_lerobot plugins' config directories (and our config nodes) to the search path of our configs.

Hydra imports this module in every Hydra app of the environment, so it imports nothing of molmo_lerobot's
until the search path is that of our configs (``conf/``): :func:`molmo_lerobot.config.add_plugin_configs`.
"""

from __future__ import annotations

from pathlib import Path

from hydra.core.config_search_path import ConfigSearchPath
from hydra.plugins.search_path_plugin import SearchPathPlugin


class MolmoLerobotSearchPath(SearchPathPlugin):
    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        from molmo_lerobot.paths import data_path

        paths = {Path(e.path.removeprefix("file://")).resolve() for e in search_path.get_path()
                 if e.path and "://" not in e.path.removeprefix("file://")}
        if data_path("conf").resolve() not in paths:
            return  # some other Hydra app in this process
        from molmo_lerobot.config import add_plugin_configs

        add_plugin_configs(search_path)
