"""Built-in plugin contributing the core Hydra config directory (``conf/``)."""

from __future__ import annotations

from molmo_lerobot import hookimpl
from molmo_lerobot.paths import data_path


@hookimpl
def molmo_config_dirs() -> list[str]:
    return [str(data_path("conf"))]
