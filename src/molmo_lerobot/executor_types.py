"""Executors as a plugin kind: what ``executor=<name>`` runs a run's episode plans on.

An :class:`ExecutorType` (hook ``molmo_executors``) names its options model, the one statement of
the ``executor.<key>`` options and their defaults (Hydra's ``executor/<name>`` config node is made
from it), and its factory. The built-in ``local`` and ``ray`` are in
:mod:`molmo_lerobot.runner.builtin_executors`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel, ConfigDict, ValidationError

#: ``factory(workers, options, timeout_s, retries, fork_servers)``: the executor of one run (a
#: :class:`~molmo_lerobot.runner.supervisor.Supervisor`; ``fork_servers``: the run's
#: :class:`~molmo_lerobot.runner.forkserver.ForkServerPool` or None)
ExecutorFactory = Callable[[int, Any, float, int, Any], Any]


class ExecutorOptions(BaseModel):
    """An executor's ``executor.<key>`` options (``name`` is the executor's): known keys, strict types."""

    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)

    name: str


@dataclass(frozen=True)
class ExecutorType:
    """One ``executor=<name>``: its options model and the factory of its executor."""

    name: str
    options: type[ExecutorOptions]
    factory: ExecutorFactory
    description: str = ""
    aliases: tuple[str, ...] = ()

    def defaults(self) -> dict[str, Any]:
        """The options' defaults: Hydra's ``executor/<name>`` node."""
        return self.options.model_validate({"name": self.name}).model_dump()

    def validate(self, options: Mapping[str, Any]) -> ExecutorOptions:
        """``options`` (the run's ``executor`` block) as this executor's model; ``ValueError`` with
        one line per problem, each naming ``executor.<key>``."""
        try:
            return self.options.model_validate({**options, "name": self.name})
        except ValidationError as exc:
            raise ValueError("\n".join(self._problem(e) for e in exc.errors())) from None

    def _problem(self, error: Any) -> str:
        key = "executor." + ".".join(str(p) for p in error["loc"])
        if error["type"] == "extra_forbidden":
            known = ", ".join(k for k in self.options.model_fields if k != "name")
            return f"{key}: executor {self.name} has no such option (options: {known})"
        msg = error["msg"]
        if error["type"] == "executor":
            return f"{key}: {msg}"
        return f"{key}: {msg[:1].lower()}{msg[1:]}, got {error['input']!r}"
