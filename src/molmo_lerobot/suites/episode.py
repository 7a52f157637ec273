"""What every env suite's episode spec is (:class:`~molmo_lerobot.suites.libero.LiberoEpisode`,
:class:`~molmo_lerobot.suites.pusht.PushTEpisode`): a frozen dataclass whose identity is its content."""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

from molmo_lerobot.hashing import content_sha256


class SuiteEpisode:
    """Base of an env suite's frozen episode dataclass: :attr:`digest` is its identity."""

    @property
    def digest(self) -> str:
        """SHA-256 of the episode's canonical JSON (keys sorted, ASCII escapes)."""
        fields: Any = asdict(self)  # type: ignore[call-overload]  # subclasses are dataclasses
        return content_sha256(fields, ensure_ascii=True).hex()
