"""Where shipped data lives: inside the wheel (``_data/``) or at the repository root (editable)."""

from __future__ import annotations

from pathlib import Path

_PKG = Path(__file__).resolve().parent


def data_path(name: str) -> Path:
    """The shipped top-level directory ``name`` (``conf`` or ``benchmarks``)."""
    for candidate in (_PKG / "_data" / name, _PKG.parents[1] / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"shipped directory {name!r} not found next to {_PKG}")
