"""Per-worker dataset shards: where they live, and how a finished one is told from a torn one.

Each worker writes its episodes into LeRobot datasets under ``output_dir/dataset_shards/``
named ``<session>-<worker_id>-s<seq>``. The session is unique per ``molmo-eval`` invocation
and the worker id per worker process (a replacement worker gets a new generation), so
shards never collide, also across ``resume=true``. A shard counts only once its writer has
been finalized and its marker file (:data:`MARKER`) is written atomically; a shard left by a
killed worker has no marker and is skipped at merge time, never merged half-written.
"""

from __future__ import annotations

import json
import re
import secrets
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_write

SHARDS_DIR = "dataset_shards"
MARKER = "meta/molmo_shard.json"
_NAME = re.compile(r"^(?P<session>[0-9T]+-[0-9a-f]+)-w(?P<w>\d+)g(?P<g>\d+)-s(?P<seq>\d+)$")


def new_session() -> str:
    """A run-invocation token: sortable by start time, unique by its random suffix."""
    return f"{datetime.now(UTC):%Y%m%dT%H%M%S}-{secrets.token_hex(3)}"


def shard_name(session: str, worker_id: str, seq: int) -> str:
    return f"{session}-{worker_id}-s{seq:03d}"


@dataclass
class Shard:
    """One shard directory; ``episodes`` (from its marker) is empty when it is incomplete."""

    root: Path
    complete: bool
    episodes: list[dict[str, Any]] = field(default_factory=list)
    discarded: list[dict[str, Any]] = field(default_factory=list)

    @property
    def sort_key(self) -> tuple:
        m = _NAME.match(self.root.name)
        if not m:
            return (self.root.name, 0, 0, 0)
        return (m["session"], int(m["w"]), int(m["g"]), int(m["seq"]))


def write_marker(root: Path, record: dict[str, Any]) -> None:
    """Declare a finalized shard complete (atomic: a torn write never counts; no link below ``root``)."""
    atomic_write(root / MARKER, json.dumps(record), root=root)


def list_shards(output_dir: Path) -> list[Shard]:
    """Every shard under ``output_dir``, oldest first; torn ones have ``complete=False``."""
    base = Path(output_dir) / SHARDS_DIR
    fileio.refuse_link(base)  # shards from elsewhere must not be merged into this run's dataset
    shards: list[Shard] = []
    if not base.is_dir():
        return shards
    for root in base.iterdir():
        if not root.is_dir():
            continue
        try:
            record = json.loads((root / MARKER).read_text())
            shards.append(Shard(root, True, list(record["episodes"]), list(record.get("discarded", []))))
        except (OSError, ValueError, KeyError, TypeError):
            shards.append(Shard(root, False))
    return sorted(shards, key=lambda s: s.sort_key)
