"""``policy=scripted``'s options, which it hands every scripted expert it dispatches to."""

from __future__ import annotations

from typing import Annotated

from molmo_lerobot.options import bounded
from molmo_lerobot.policies.base import MAX_CHUNK, PolicyOptions


class ScriptedOptions(PolicyOptions):
    """The options every scripted expert reads."""

    name: str = "scripted"
    #: policy steps per action chunk
    chunk: Annotated[int, bounded(1, MAX_CHUNK, integer=True)] = 12
    #: the arm's joint speed while moving between phases (rad/s)
    speed: Annotated[int | float, bounded(1e-3, 100.0, integer=False)] = 1.0
