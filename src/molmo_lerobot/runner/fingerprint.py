"""Content hashes of the policy checkpoints a run uses, so a run knows exactly which weights it scored (the
robots' are their benchmark kind's: :meth:`~molmo_lerobot.benchmark_kinds.BenchmarkKind.robots`).

``run.json`` and ``results.json`` record them under ``policy_checkpoint`` and ``robots``; ``resume=true``
refuses to continue a run whose checkpoint changed since (a retrained ``checkpoints/last``
keeps its path but not its content) or whose robots differ, and ``molmo-compare`` refuses runs of
different robots.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

#: policy config keys that name a checkpoint (a file or a ``save_pretrained`` directory)
CHECKPOINT_KEYS = ("path", "checkpoint", "checkpoint_path", "pretrained_path")


def checkpoint_sha256(path: Path) -> dict[str, Any]:
    """sha256 over every file under ``path`` (weights, config, processors): relative name, size, content.

    Symlinks are followed (``checkpoints/last``), so the hash is the content the policy loads.
    """
    path = Path(path).expanduser()
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    total = hashlib.sha256()
    n_bytes = 0
    for f in files:
        with open(f, "rb") as fh:
            digest = hashlib.file_digest(fh, "sha256").hexdigest()
        size = f.stat().st_size
        n_bytes += size
        rel = f.name if f == path else f.relative_to(path).as_posix()
        total.update(f"{rel}\0{size}\0{digest}\n".encode())
    return {"path": str(path.resolve()), "sha256": total.hexdigest(), "n_files": len(files), "bytes": n_bytes}


def policy_checkpoints(policy_cfg: dict[str, Any]) -> dict[str, Any] | None:
    """``{config key: checkpoint_sha256(...)}`` for each local checkpoint the policy config names.

    A value that is not a local path (a Hub repo id, a server address) is recorded as given with
    ``sha256: null``: its content cannot be checked here. None when the policy names no checkpoint.
    """
    out: dict[str, Any] = {}
    for key in CHECKPOINT_KEYS:
        value = policy_cfg.get(key)
        if not isinstance(value, str) or not value or value == "???":
            continue
        local = Path(value).expanduser()
        out[key] = checkpoint_sha256(local) if local.exists() else {"path": value, "sha256": None}
    return out or None
