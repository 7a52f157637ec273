"""The built-in executors, provided by the core plugin (:mod:`molmo_lerobot.conf_plugin`): ``local``, worker
processes on this machine (:mod:`~molmo_lerobot.runner.local`), and ``ray``, simulator actors on a Ray cluster
(:mod:`~molmo_lerobot.runner.ray_executor`); each factory imports its executor only when a run makes one."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pydantic import ValidationInfo, field_validator
from pydantic_core import PydanticCustomError

from molmo_lerobot.executor_types import ExecutorOptions, ExecutorType
from molmo_lerobot.runner.forkserver import START_METHODS
from molmo_lerobot.runner.placement import check_devices

if TYPE_CHECKING:
    from molmo_lerobot.runner.forkserver import ForkServerPool
    from molmo_lerobot.runner.supervisor import Supervisor


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
