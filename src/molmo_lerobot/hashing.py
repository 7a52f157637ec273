"""Content hashes: the canonical JSON of a value (keys sorted) and its SHA-256.

Equal content gives equal text, whatever the key order or the file layout it came from. The
digests seed episodes and camera randomizations and identify benchmarks, so their text never
changes: :func:`episode_digest`, the run's episode seeds and ``Benchmark.sha256`` each keep the
spelling they were published with (``spaced`` separators, ``ensure_ascii`` escapes), pinned by
``tests/test_hashing.py``. Depends on nothing else of the package.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from pydantic import BaseModel


def canonical_json(value: Any, *, ensure_ascii: bool = False, spaced: bool = False) -> str:
    """JSON with sorted keys; a pydantic model is dumped in JSON mode first.

    Compact (``,`` and ``:``) unless ``spaced`` (``, `` and ``: ``); non-ASCII characters as
    they are unless ``ensure_ascii`` (``\\uXXXX`` escapes)."""
    if isinstance(value, BaseModel):
        value = value.model_dump(mode="json")
    separators = (", ", ": ") if spaced else (",", ":")
    return json.dumps(value, sort_keys=True, separators=separators, ensure_ascii=ensure_ascii)


def content_sha256(value: Any, *, prefix: str = "", ensure_ascii: bool = False,
                   spaced: bool = False) -> bytes:
    """SHA-256 of ``prefix`` + :func:`canonical_json` of ``value``, UTF-8 encoded."""
    text = prefix + canonical_json(value, ensure_ascii=ensure_ascii, spaced=spaced)
    return hashlib.sha256(text.encode("utf-8")).digest()


def episode_digest(episode: Any) -> bytes:
    """SHA-256 of an episode's content (a model or its JSON dict): what seeds its randomizations."""
    return content_sha256(episode, ensure_ascii=True, spaced=True)
