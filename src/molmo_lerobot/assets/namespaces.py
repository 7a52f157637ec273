"""Dataset ids ``ns/sub/name`` with Minari's namespace rules (a namespace is a directory-like prefix)."""

from __future__ import annotations

import re

from molmo_lerobot.errors import MolmoError

NAMESPACE_RE = re.compile(r"[-_\w][-_\w/]*[-_\w]+")


class NamespaceError(MolmoError, ValueError):
    """An invalid namespace or dataset id; the message names it."""


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
        raise NamespaceError(f"invalid dataset id {dataset_id!r}: name {name!r} must use letters, digits, "
                             "'-', '_', '.'")
    if namespace:
        validate_namespace_id(namespace)
    return namespace or None, name
