"""Where data lives: ours (the wheel's ``_data/``, or the repository root when editable) and
assets inside installed registry packages."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

_PKG = Path(__file__).resolve().parent


def data_path(name: str) -> Path:
    """The shipped top-level directory ``name`` (``conf`` or ``benchmarks``)."""
    for candidate in (_PKG / "_data" / name, _PKG.parents[1] / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"shipped directory {name!r} not found next to {_PKG}")


def package_asset_dir(package: str, *parts: str, marker: str, what: str, install: str | None = None) -> Path:
    """``parts`` inside the installed ``package``, checked to hold ``marker``; ``what`` names who needs it
    and ``install`` how to get the package (default ``pip install <package>``)."""
    found = importlib.util.find_spec(package)
    if found is None or not found.submodule_search_locations:
        dist = package.replace("_", "-")
        raise FileNotFoundError(f"{what}: the {dist!r} package is not installed ({install or f'pip install {dist}'})")
    path = Path(next(iter(found.submodule_search_locations))).joinpath(*parts)
    if not (path / marker).exists():
        raise FileNotFoundError(f"{what}: assets not found at {path} ({package} layout changed?)")
    return path


def home_dir() -> Path:
    """Our cache dir: ``$MOLMO_LEROBOT_HOME``, else ``~/.cache/molmo_lerobot``. It may be a link; what is
    written below it goes through :mod:`molmo_lerobot.fileio` with it as the root."""
    return Path(os.environ.get("MOLMO_LEROBOT_HOME") or Path.home() / ".cache" / "molmo_lerobot")


#: Where ``molmo-resources install --preset molmospaces`` puts MolmoSpaces' data when no
#: ``MLSPACES_ASSETS_DIR`` is set (their layout: ``scenes/``, ``objects/``, ``grasps/``, ``robots/``).
DEFAULT_MOLMOSPACES_ASSETS_DIR = Path("~/.cache/molmo_lerobot/molmospaces/assets")


def molmospaces_assets_dir(configured: str | Path | None = None) -> Path:
    """MolmoSpaces' assets dir: ``configured``, else ``$MLSPACES_ASSETS_DIR``, else our install dir."""
    value = configured or os.environ.get("MLSPACES_ASSETS_DIR") or DEFAULT_MOLMOSPACES_ASSETS_DIR
    return Path(value).expanduser()
