"""Namespaces for benchmark and dataset ids ``ns/sub/name`` (Minari's semantics).

A namespace is a directory-like prefix of ids; namespaces nest, each carries a small
metadata JSON (``namespace_metadata.json`` in its directory), and only empty ones can be
deleted. Locally they live under a datasets root (``$MOLMO_LEROBOT_DATASETS``, default
``~/.cache/molmo_lerobot/datasets``): ``<root>/<ns>/<sub>/namespace_metadata.json`` and
datasets as the other directories, ``<root>/<ns>/<sub>/<name>/``. A remote (directory or
Hugging Face repo, see :mod:`molmo_lerobot.resources.remotes`) uses the same layout.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

from molmo_lerobot.fileio import atomic_write

NAMESPACE_RE = re.compile(r"[-_\w][-_\w/]*[-_\w]+")
METADATA_FILE = "namespace_metadata.json"


class NamespaceError(ValueError):
    """An invalid, missing, existing or non-empty namespace; the message names it."""


def validate_namespace_id(namespace: str) -> str:
    """Return ``namespace`` if it is a valid id (``[-_\\w][-_\\w/]*[-_\\w]+``, no empty parts), else raise."""
    if not isinstance(namespace, str) or not NAMESPACE_RE.fullmatch(namespace) or "//" in namespace:
        raise NamespaceError(
            f"invalid namespace {namespace!r}: use letters, digits, '-', '_' and '/' between parts "
            "(at least 2 characters, no leading, trailing or double '/')"
        )
    return namespace


def parse_dataset_id(dataset_id: str) -> tuple[str | None, str]:
    """Split ``ns/sub/name`` into ``("ns/sub", "name")``; ``name`` alone has no namespace."""
    if not isinstance(dataset_id, str) or not dataset_id or dataset_id.startswith("/") or dataset_id.endswith("/"):
        raise NamespaceError(f"invalid dataset id {dataset_id!r}: expected [namespace/]name")
    namespace, _, name = dataset_id.rpartition("/")
    if not re.fullmatch(r"[-_.\w]+", name) or name in (".", ".."):
        raise NamespaceError(f"invalid dataset id {dataset_id!r}: name {name!r} must use letters, digits, '-', '_', '.'")
    if namespace:
        validate_namespace_id(namespace)
    return namespace or None, name


def datasets_root(root: str | os.PathLike | None = None) -> Path:
    if root is not None:
        return Path(root)
    env = os.environ.get("MOLMO_LEROBOT_DATASETS")
    return Path(env) if env else Path.home() / ".cache" / "molmo_lerobot" / "datasets"


def _ns_dir(namespace: str, root: str | os.PathLike | None) -> Path:
    return datasets_root(root) / validate_namespace_id(namespace)


def namespace_exists(namespace: str, root: str | os.PathLike | None = None) -> bool:
    return (_ns_dir(namespace, root) / METADATA_FILE).is_file()


def _write_metadata(directory: Path, metadata: dict) -> None:
    if not isinstance(metadata, dict):
        raise NamespaceError(f"namespace metadata must be a JSON object, got {type(metadata).__name__}")
    text = json.dumps(metadata, indent=1, sort_keys=True)  # raises on non-JSON values before writing
    directory.mkdir(parents=True, exist_ok=True)
    atomic_write(directory / METADATA_FILE, text)


def create_namespace(namespace: str, metadata: dict | None = None, root: str | os.PathLike | None = None,
                     exist_ok: bool = False) -> Path:
    """Create ``namespace`` (and its missing parents, with empty metadata); returns its directory."""
    directory = _ns_dir(namespace, root)
    metadata = {} if metadata is None else metadata
    if not isinstance(metadata, dict):
        raise NamespaceError(f"namespace metadata must be a JSON object, got {type(metadata).__name__}")
    if (directory / METADATA_FILE).is_file():
        if exist_ok:
            return directory
        raise NamespaceError(f"namespace {namespace!r} already exists")
    if directory.is_dir() and any(p.name != METADATA_FILE for p in directory.iterdir()):
        raise NamespaceError(f"{directory} already exists and is not a namespace (is it a dataset?)")
    parts = namespace.split("/")
    for i in range(1, len(parts)):
        parent = "/".join(parts[:i])
        pdir = datasets_root(root) / parent
        if not (pdir / METADATA_FILE).is_file():
            if len(parent) >= 2 and NAMESPACE_RE.fullmatch(parent):
                _write_metadata(pdir, {})
            else:
                pdir.mkdir(parents=True, exist_ok=True)
    _write_metadata(directory, dict(metadata))
    return directory


def get_namespace_metadata(namespace: str, root: str | os.PathLike | None = None) -> dict:
    path = _ns_dir(namespace, root) / METADATA_FILE
    if not path.is_file():
        raise NamespaceError(f"namespace {namespace!r} does not exist under {datasets_root(root)}")
    try:
        data = json.loads(path.read_text())
    except ValueError as exc:
        raise NamespaceError(f"{path}: invalid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise NamespaceError(f"{path}: expected a JSON object")
    return data


def update_namespace(namespace: str, metadata: dict, root: str | os.PathLike | None = None,
                     replace: bool = False) -> dict:
    """Merge ``metadata`` into (or with ``replace=True`` replace) a namespace's metadata; returns it."""
    current = get_namespace_metadata(namespace, root)
    new = dict(metadata) if replace else {**current, **metadata}
    _write_metadata(_ns_dir(namespace, root), new)
    return new


def _children(directory: Path) -> list[Path]:
    return sorted(p for p in directory.iterdir() if p.is_dir() and not p.name.startswith("."))


def delete_namespace(namespace: str, root: str | os.PathLike | None = None) -> None:
    """Delete an empty namespace (no datasets, no sub-namespaces)."""
    directory = _ns_dir(namespace, root)
    if not (directory / METADATA_FILE).is_file():
        raise NamespaceError(f"namespace {namespace!r} does not exist under {datasets_root(root)}")
    children = _children(directory)
    others = [p for p in directory.iterdir() if p.is_file() and p.name != METADATA_FILE]
    if children or others:
        names = ", ".join(p.name for p in (children + others)[:5])
        raise NamespaceError(f"namespace {namespace!r} is not empty ({names}); delete its datasets first")
    shutil.rmtree(directory)


def list_local_namespaces(root: str | os.PathLike | None = None) -> list[str]:
    base = datasets_root(root)
    if not base.is_dir():
        return []
    return sorted(p.parent.relative_to(base).as_posix() for p in base.rglob(METADATA_FILE))


def list_local_datasets(namespace: str | None = None, root: str | os.PathLike | None = None) -> list[str]:
    """Dataset ids below ``namespace`` (all of them when ``None``): directories that are not namespaces."""
    base = datasets_root(root)
    start = _ns_dir(namespace, root) if namespace else base
    if not start.is_dir():
        return []
    out: list[str] = []

    def walk(directory: Path) -> None:
        for child in _children(directory):
            if (child / METADATA_FILE).is_file():
                walk(child)
            elif directory == base or (directory / METADATA_FILE).is_file():
                out.append(child.relative_to(base).as_posix())

    if namespace is None or (start / METADATA_FILE).is_file():
        walk(start)
    return sorted(out)


def dataset_dir(dataset_id: str, root: str | os.PathLike | None = None, create_namespaces: bool = False) -> Path:
    """The local directory of ``ns/sub/name``; optionally create its namespaces first."""
    namespace, name = parse_dataset_id(dataset_id)
    if namespace and create_namespaces:
        create_namespace(namespace, root=root, exist_ok=True)
    return datasets_root(root) / dataset_id


def list_remote_namespaces(remote) -> list[str]:
    """Namespaces published on a remote (a :class:`~molmo_lerobot.resources.Remote` or its URL)."""
    from molmo_lerobot.resources.remotes import open_remote

    remote = open_remote(remote) if isinstance(remote, (str, os.PathLike)) else remote
    found = [f[: -len(METADATA_FILE) - 1] for f in remote.list_files() if f.endswith("/" + METADATA_FILE)]
    return sorted(ns for ns in found if NAMESPACE_RE.fullmatch(ns))


def get_remote_namespace_metadata(remote, namespace: str) -> dict:
    from molmo_lerobot.resources.errors import ResourceError
    from molmo_lerobot.resources.remotes import open_remote

    remote = open_remote(remote) if isinstance(remote, (str, os.PathLike)) else remote
    try:
        return json.loads(remote.read_bytes(f"{validate_namespace_id(namespace)}/{METADATA_FILE}"))
    except ResourceError:
        raise NamespaceError(f"namespace {namespace!r} not found on {remote.url}") from None


def upload_namespace(namespace: str, remote, root: str | os.PathLike | None = None) -> None:
    """Publish a local namespace's metadata file to a remote (datasets are pushed by the exporter)."""
    from molmo_lerobot.resources.remotes import open_remote

    remote = open_remote(remote) if isinstance(remote, (str, os.PathLike)) else remote
    metadata = get_namespace_metadata(namespace, root)
    remote.put_bytes(f"{namespace}/{METADATA_FILE}", json.dumps(metadata, indent=1, sort_keys=True).encode(),
                     message=f"Namespace {namespace}")
