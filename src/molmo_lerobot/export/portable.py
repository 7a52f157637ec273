"""What the dataset says about this machine: no absolute path of it.

``dataset/`` is what ``push=true`` publishes and what people copy, so the run summary, the
eval info and the eval records written into it name places portably: a path inside the run
directory becomes relative to it (``.``, ``dataset``), any other absolute path becomes
``<local>/<its last component>`` (``<local>/pick_v1``: the benchmark is identified by
``benchmark.name`` and ``benchmark.sha256`` beside it; ``<local>/assets`` for a cache), also
inside text such as an error message. The run directory's own ``results.json`` and
``episodes.jsonl`` keep the full paths.
"""

from __future__ import annotations

import os
import re
from pathlib import Path, PurePosixPath
from typing import Any

#: an absolute POSIX path: a ``/`` that starts a word (not ``a/b``, not the ``//`` of a URL)
_ABSOLUTE = re.compile(r"(?<![\w.~:/-])/[^\s'\"`,;:()\[\]{}<>|]*")
LOCAL = "<local>"


def portable(value: Any, run_dir: Path) -> Any:
    """``value`` (JSON-like: dicts, lists, strings, numbers) with every absolute path made portable
    (in keys too)."""
    roots = {str(Path(run_dir)), str(Path(run_dir).resolve())}

    def replace(match: re.Match[str]) -> str:
        path = match.group(0).rstrip(".")
        tail = match.group(0)[len(path):]
        for root in roots:
            if path == root or path.startswith(root.rstrip("/") + "/"):
                return os.path.relpath(path, root) + tail
        name = PurePosixPath(path).name
        return (f"{LOCAL}/{name}" if name else LOCAL) + tail

    def walk(v: Any) -> Any:
        if isinstance(v, str):
            return _ABSOLUTE.sub(replace, v)
        if isinstance(v, dict):
            return {walk(k): walk(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [walk(x) for x in v]
        return v

    return walk(value)
