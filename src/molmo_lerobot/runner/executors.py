"""Executors as a plugin kind: what ``executor=<name>`` runs a run's episode plans on.

An :class:`ExecutorType` (hook ``molmo_executors``) names its options model, the one statement of
the ``executor.<key>`` options and their defaults (Hydra's ``executor/<name>`` config node is made
from it), and its factory. The built-in ``local`` (worker processes) and ``ray`` (Ray actors) are
provided by the core plugin :mod:`molmo_lerobot.conf_plugin`; their factories import their
executor only when a run makes one.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ConfigDict, ValidationError, ValidationInfo, field_validator
from pydantic_core import PydanticCustomError

from molmo_lerobot.runner.forkserver import START_METHODS
from molmo_lerobot.runner.placement import check_devices

if TYPE_CHECKING:
    from molmo_lerobot.runner.forkserver import ForkServerPool
    from molmo_lerobot.runner.supervisor import Supervisor

#: ``factory(workers, options, timeout_s, retries, fork_servers)``: the executor of one run
ExecutorFactory = Callable[[int, Any, float, int, "ForkServerPool | None"], "Supervisor"]


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


class LocalOptions(ExecutorOptions):
    """``executor=local``: worker processes on this machine, supervised (crash: retry; hang: timeout)."""

    #: forkserver (workers forked from a server that preloaded their imports) | spawn
    start_method: str = "forkserver"
    #: EGL device ids to render on, round-robin over workers (null: every GPU, unless MUJOCO_EGL_DEVICE_ID
    #: is set; []: never set)
    egl_devices: list[int] | None = None
    #: CUDA device indices for policy.device=cuda|auto, round-robin (null: every visible GPU; []: leave
    #: policy.device)
    cuda_devices: list[int] | None = None

    @field_validator("start_method", mode="before")
    @classmethod
    def _start_method(cls, value: Any) -> Any:
        if value not in START_METHODS:
            raise PydanticCustomError("executor", f"expected one of {list(START_METHODS)}, got {value!r}")
        return value

    @field_validator("egl_devices", "cuda_devices", mode="before")
    @classmethod
    def _devices(cls, value: Any, info: ValidationInfo) -> Any:
        try:
            check_devices({str(info.field_name): value})
        except ValueError as exc:
            raise PydanticCustomError("executor", str(exc).split(": ", 1)[1]) from None
        return value


class RayOptions(ExecutorOptions):
    """``executor=ray``: simulator actors on a Ray cluster, supervised like the local pool; with
    ``policy.serve=true`` one policy server per node, each node's actors its clients (docs/scaling.md)."""

    #: null: start a local cluster with num_cpus=workers; "auto": join a running cluster
    address: str | None = None
    include_dashboard: bool = False
    #: Ray resources reserved by each simulator actor
    num_cpus_per_worker: float = 1
    #: e.g. 1 for a GPU policy, 0.25 to pack four actors per GPU (policy.serve's node servers take one each)
    num_gpus_per_worker: float = 0


def _local(workers: int, options: Any, timeout_s: float, retries: int,
           fork_servers: ForkServerPool | None) -> Supervisor:
    from molmo_lerobot.runner.local import LocalExecutor

    return LocalExecutor(workers, start_method=options.start_method, fork_servers=fork_servers,
                         timeout_s=timeout_s, retries=retries)


def _ray(workers: int, options: Any, timeout_s: float, retries: int,
         fork_servers: ForkServerPool | None) -> Supervisor:
    from molmo_lerobot.runner.ray_executor import RayExecutor

    return RayExecutor(workers, address=options.address, include_dashboard=options.include_dashboard,
                       num_cpus_per_worker=options.num_cpus_per_worker,
                       num_gpus_per_worker=options.num_gpus_per_worker, timeout_s=timeout_s, retries=retries)


LOCAL = ExecutorType("local", LocalOptions, _local, "worker processes on this machine")
RAY = ExecutorType("ray", RayOptions, _ray, "simulator actors on a Ray cluster")
