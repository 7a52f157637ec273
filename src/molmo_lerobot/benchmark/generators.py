"""Benchmark generators as a plugin kind: what ``molmo-bench generate <name>`` runs.

A :class:`BenchmarkGenerator` (hook ``molmo_generators``) is provided by the content whose scenes its
episodes use; the built-in ones by the content's generator modules (``content/*/generate*.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

#: ``generate(task, n_houses, episodes_per_house, seed, name)`` → (JSON-ready episodes, benchmark metadata)
GenerateFn = Callable[[str, int, int, int, str], tuple[list[dict[str, Any]], dict[str, Any]]]


@dataclass(frozen=True)
class BenchmarkGenerator:
    """One ``molmo-bench generate <name>``: the tasks it makes episodes of and the function that makes them."""

    name: str
    description: str
    #: the ``--task`` values it takes; the first is the default
    tasks: tuple[str, ...]
    generate: GenerateFn
    aliases: tuple[str, ...] = ()

    def run(self, task: str | None, houses: int, per_house: int, seed: int,
            name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        """The episodes and metadata for ``--task task`` (None: the first task); ``ValueError`` for another task."""
        task = task or self.tasks[0]
        if task not in self.tasks:
            raise ValueError(f"generate: generator {self.name!r} makes {', '.join(map(repr, self.tasks))} episodes "
                             f"only, not --task {task!r}")
        return self.generate(task, houses, per_house, seed, name)
