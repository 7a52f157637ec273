"""Version records at the roots of the cache and install dirs: ``{data_type: {source: values}}`` files
that say which versions a cache holds (``values`` a sorted list) and which one an install dir links
(``values`` a version). Ours is ``.molmo/installed.json``; a layout may keep another tool's beside it."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Literal

from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.resources.manifests import check_local, read_json

Values = Literal["list", "str"]
#: an edit of one record, in place
Edit = Callable[[dict], None]


def update_record(path: Path, edit: Edit, values: Values, *, root: Path, indent: int = 1) -> None:
    """Edit the record ``path`` in place (written atomically, walking from ``root``); ours sorted with
    ``indent`` 1, another tool's as it writes them."""
    data = check_local(read_json(path), path, values) if path.is_file() else {}
    edit(data)
    atomic_write(path, json.dumps(data, indent=indent, sort_keys=indent == 1), root=root)


def cached_versions(records: Iterable[Path]) -> dict[str, dict[str, list[str]]]:
    """``{data_type: {source: [versions]}}`` that any of the cache ``records`` lists."""
    out: dict[str, dict[str, list[str]]] = {}
    for path in records:
        if path.is_file():
            for data_type, sources in check_local(read_json(path), path, "list").items():
                for source, versions in sources.items():
                    have = out.setdefault(data_type, {}).setdefault(source, [])
                    have[:] = sorted(set(have) | set(versions))
    return {t: {s: v for s, v in src.items() if v} for t, src in out.items() if any(src.values())}


def linked_versions(records: Iterable[Path]) -> dict[str, dict[str, str]]:
    """``{data_type: {source: version}}`` the install dir ``records`` point at (later records win)."""
    out: dict[str, dict[str, str]] = {}
    for path in records:
        if path.is_file():
            for data_type, sources in check_local(read_json(path), path, "str").items():
                out.setdefault(data_type, {}).update({s: v for s, v in sources.items() if v is not None})
    return {t: src for t, src in out.items() if src}
