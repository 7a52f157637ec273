"""Manifests and indexes read from remotes and caches: schemas, and one-line errors for bad ones.

Everything here comes from outside (a remote, a cache another process or tool wrote), so
each field is checked for type and shape before use; a bad one is a :class:`ResourceError`
naming the file and the field.
"""

from __future__ import annotations

import gzip
import json
import posixpath
import re
from collections.abc import Mapping
from pathlib import Path, PurePosixPath
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictInt, StrictStr, ValidationError

from molmo_lerobot.resources.errors import ResourceError

#: Archive names become file names in the cache's bookkeeping: no separators, no dot-dot.
ARCHIVE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")


class ArchiveEntry(BaseModel):
    model_config = ConfigDict(extra="allow")

    size: Annotated[StrictInt, Field(ge=0)]
    sha256: Annotated[StrictStr, Field(pattern=r"^[0-9a-f]{64}$")] | None = None
    n_files: Annotated[StrictInt, Field(ge=0)] | None = None


class VersionManifest(BaseModel):
    """Our remote ``manifest.json`` (and, converted, MolmoSpaces' archive→size manifest)."""

    model_config = ConfigDict(extra="allow")

    format: StrictInt | StrictStr = 1
    data_type: StrictStr
    source: StrictStr
    version: StrictStr
    link: Literal["dir", "file"]
    uid_depth: Annotated[StrictInt, Field(ge=0, le=64)]
    archives: dict[str, ArchiveEntry]


def _field(loc: tuple) -> str:
    return ".".join(str(p) for p in loc) or "(top level)"


def one_line(exc: ValidationError) -> str:
    err = exc.errors()[0]
    more = f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
    return f"field {_field(err['loc'])}: {err['msg']}{more}"


def parse_manifest(data: object, where: str) -> dict:
    """Validate a version manifest; returns it as a plain dict."""
    try:
        manifest = VersionManifest.model_validate(data)
    except ValidationError as exc:
        raise ResourceError(f"{where}: {one_line(exc)}") from None
    for name in manifest.archives:
        if not ARCHIVE_NAME.match(name):
            raise ResourceError(f"{where}: field archives: archive name {name!r} is not a plain file name")
    return manifest.model_dump(exclude_none=True)


def read_json(path: Path, where: str | None = None) -> object:
    """JSON from ``path`` (``.gz`` decompressed); a clear line for unreadable or malformed files."""
    where = where or str(path)
    try:
        raw = path.read_bytes()
        if path.name.endswith(".gz"):
            raw = gzip.decompress(raw)
        return json.loads(raw)
    except (OSError, EOFError, ValueError, RecursionError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc).splitlines()[0][:200]
        raise ResourceError(f"{where}: cannot be read as JSON ({type(exc).__name__}: {reason})") from None


def clean_rel(path: object) -> bool:
    """A relative POSIX path with no empty, ``.`` or ``..`` component."""
    return (isinstance(path, str) and bool(path) and not path.startswith("/") and "\\" not in path
            and "\0" not in path and all(p not in ("", ".", "..") for p in path.split("/")))


def link_escapes(member: str, target: str) -> bool:
    """Whether a link at ``member`` to ``target`` leaves the tree, read as text."""
    if not target or PurePosixPath(target).is_absolute():
        return True
    resolved = posixpath.normpath(posixpath.join(posixpath.dirname(member), target))
    return resolved == ".." or resolved.startswith("../") or resolved.startswith("/")


def check_index(entries: object, archives: Mapping[str, object], where: str) -> dict[str, dict[str, list]]:
    """Validate ``{archive: {path: entry}}`` against the manifest's archives.

    Entries are ``[size, sha256]``, ``["->", target]`` or ``[None, None]`` (a MolmoSpaces
    leaf: a file, link or empty dir of unknown size). Paths must be clean, held by one
    archive only, and never below another entry (that entry would have to be a directory).
    """
    if not isinstance(entries, dict):
        raise ResourceError(f"{where}: must hold a JSON object {{archive: {{path: entry}}}}")
    if set(entries) != set(archives):
        extra, missing = sorted(set(entries) - set(archives)), sorted(set(archives) - set(entries))
        raise ResourceError(f"{where}: lists other archives than the manifest "
                            f"(extra {extra[:3]}, missing {missing[:3]})")
    owner: dict[str, str] = {}
    for archive, files in entries.items():
        if not isinstance(files, dict):
            raise ResourceError(f"{where}: archive {archive}: must map paths to entries")
        for path, entry in files.items():
            at = f"{where}: archive {archive}: path {path!r}"
            if not clean_rel(path):
                raise ResourceError(f"{at} is not a clean relative path")
            if not _entry_ok(entry):
                raise ResourceError(f"{at}: entry {json.dumps(entry)[:80]} is not [size, sha256], ['->', target] "
                                    "or [null, null]")
            if entry[0] == "->" and link_escapes(path, entry[1]):
                raise ResourceError(f"{at} is a link to {entry[1]!r} outside the version")
            if path in owner:
                raise ResourceError(f"{at} is also in archive {owner[path]}")
            owner[path] = archive
    for path in owner:
        parent = posixpath.dirname(path)
        while parent:
            if parent in owner:
                raise ResourceError(f"{where}: path {path!r} (archive {owner[path]}) lies below {parent!r} "
                                    f"(archive {owner[parent]}), which is not a directory")
            parent = posixpath.dirname(parent)
    return entries


def _entry_ok(entry: object) -> bool:
    if not isinstance(entry, list) or len(entry) != 2:
        return False
    a, b = entry
    if a == "->":
        return isinstance(b, str) and bool(b) and "\0" not in b
    if a is None:
        return b is None
    return (isinstance(a, int) and not isinstance(a, bool) and a >= 0 and isinstance(b, str)
            and re.fullmatch(r"[0-9a-f]{64}", b) is not None)


def check_local(data: object, path: Path, values: Literal["list", "str"]) -> dict:
    """A local manifest ``{data_type: {source: [versions]}}`` (cache) or ``{…: version}`` (install dir)."""
    if not (isinstance(data, dict) and all(
        isinstance(sources, dict) and all(
            isinstance(src, str) and (
                (values == "list" and isinstance(v, list) and all(isinstance(x, str) for x in v))
                or (values == "str" and (v is None or isinstance(v, str))))
            for src, v in sources.items())
        for sources in data.values())):
        shape = "{data_type: {source: [versions]}}" if values == "list" else "{data_type: {source: version}}"
        raise ResourceError(f"local manifest {path}: must hold {shape}; fix or delete it")
    return data
