"""Every cache layout by the manifest ``format`` it serves, in the order a remote is probed for a
version's metadata (ours first; ours have an integer format). A new layout registers here."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from molmo_lerobot.resources.layout import Layout, OwnLayout
from molmo_lerobot.resources.molmospaces import MolmoSpacesLayout

LAYOUTS: Mapping[int | str, type[Layout]] = MappingProxyType(
    {layout.format: layout for layout in (OwnLayout, MolmoSpacesLayout)})


def layout_for(fmt: int | str | None) -> type[Layout]:
    """The layout of manifest format ``fmt`` (ours where no layout claims it)."""
    return OwnLayout if fmt is None else LAYOUTS.get(fmt, OwnLayout)
