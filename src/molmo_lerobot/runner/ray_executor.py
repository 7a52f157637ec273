"""Ray transport: each worker is a Ray actor wrapping one :class:`EpisodeWorker`.

:class:`RayExecutor` is the :class:`~molmo_lerobot.runner.supervisor.Supervisor` over it. An
actor's death (SIGKILL, segfault, OOM, node loss: ``RayActorError``) or a call failing outside
the episode's own error handling is a worker death to the supervisor.

``address=None`` starts a local cluster with ``num_cpus=workers`` (shut down at the end);
``"auto"`` or ``"ray://…"`` joins a running one. A Ray session that is already initialized in
this process is used as is and left running.

With ``policy.serve=true`` the run uses :meth:`RayExecutor.served_policy` instead of the one
local server: a policy server per node (:mod:`molmo_lerobot.serving.ray_servers`), and each
simulator actor becomes the client of the server on its own node.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot.episode_plan import EpisodePlan
from molmo_lerobot.gl import use_headless_gl
from molmo_lerobot.runner.progress import redirect_worker_output
from molmo_lerobot.runner.supervisor import (
    DEAD,
    INIT_ERROR,
    READY,
    RESULT,
    Event,
    Supervisor,
    Transport,
    WorkerStartError,
)
from molmo_lerobot.runner.worker import EpisodeWorker, WorkerJob
from molmo_lerobot.serving.ray_servers import CLIENT_CONFIG, node_servers
from molmo_lerobot.serving.run_server import serve_options

if TYPE_CHECKING:
    from molmo_lerobot.run_config import RunConfig


class SimulatorActor:
    """Body of one Ray actor: an :class:`EpisodeWorker`, or the reason it could not start.

    ``ports`` (policy.serve): the port of the policy server of each node, by node id; the
    worker's ``policy=remote`` connects to the one on the node the actor was placed on."""

    def __init__(self, job: WorkerJob, worker_id: str, ports: dict[str, int] | None = None) -> None:
        use_headless_gl()
        redirect_worker_output(job.output_dir, worker_id)  # library prints go to logs/, not through the bar
        self.worker: EpisodeWorker | None = None
        self.init_error: str | None = None
        try:
            if ports is not None:
                job = replace(job, policy={**job.policy, "port": _own_port(ports)})
            self.worker = EpisodeWorker(job, worker_id)
        except Exception as exc:
            self.init_error = f"{type(exc).__name__}: {exc}"

    def ready(self) -> tuple[str, Any]:
        if self.init_error is not None:
            return INIT_ERROR, self.init_error
        return READY, os.getpid()

    def run(self, item: EpisodePlan) -> dict[str, Any]:
        if self.worker is None:
            raise RuntimeError(f"worker could not start: {self.init_error}")
        return self.worker.run(item).to_dict()

    def close(self) -> None:
        if self.worker is not None:
            self.worker.close()


def _own_port(ports: dict[str, int]) -> int:
    import ray

    node = ray.get_runtime_context().get_node_id()
    if node not in ports:
        raise RuntimeError(f"policy.serve: no policy server on Ray node {node[:12]} (servers start on the nodes "
                           "alive when the run starts)")
    return ports[node]


@dataclass
class _Actor:
    actor: Any
    ready_ref: Any
    pid: int | None = None
    ready: bool = False
    ref: Any = None  # the running episode's call
    close_ref: Any = None
    dead: bool = False


#: Ray's logger for token authentication, and its notice that it turned token authentication on for a new
#: local cluster (its default, logged at every start); the filter drops that notice and nothing else
_RAY_AUTH_LOGGER = "ray._private.authentication.authentication_token_setup"


class _QuietAuthNotice(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith("Token authentication is enabled for this Ray cluster")


_QUIET_AUTH_NOTICE = _QuietAuthNotice()


class RayTransport(Transport):
    """Workers as Ray actors (one CPU each unless configured), started with ``max_restarts=0``."""

    def __init__(self, address: str | None = None, include_dashboard: bool = False,
                 num_cpus_per_worker: float = 1.0, num_gpus_per_worker: float = 0.0) -> None:
        self.address = address
        self.include_dashboard = include_dashboard
        self.num_cpus_per_worker = num_cpus_per_worker
        self.num_gpus_per_worker = num_gpus_per_worker
        self._owned = False
        self._actor_cls: Any = None
        self.ports: dict[str, int] | None = None  # policy.serve: each node's server
        self._held = False  # the served policy's servers still need the cluster

    def open(self, workers: int) -> None:
        import ray

        self._actor_cls = ray.remote(SimulatorActor)
        self.join(workers)

    def join(self, workers: int) -> None:
        """Start or join the cluster unless this process is connected to one."""
        import ray

        if ray.is_initialized():
            return
        use_headless_gl()  # local-cluster workers inherit the driver's environment
        logging.getLogger(_RAY_AUTH_LOGGER).addFilter(_QUIET_AUTH_NOTICE)
        kwargs: dict[str, Any] = dict(include_dashboard=self.include_dashboard, logging_level=logging.WARNING)
        if self.address is None:
            kwargs["num_cpus"] = max(1, round(workers * self.num_cpus_per_worker))
        try:
            ray.init(address=self.address, **kwargs)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = "start a local Ray cluster" if self.address is None else f"join the Ray cluster at {self.address!r}"
            raise WorkerStartError(f"could not {where}: {_short(exc)}") from None
        self._owned = True

    def close(self) -> None:
        import ray

        if self._owned and not self._held:
            ray.shutdown()
            self._owned = False

    @contextlib.contextmanager
    def held(self, workers: int) -> Iterator[None]:
        """The cluster joined (started) now and kept until the end of the block, not of the run."""
        self.join(workers)
        self._held = True
        try:
            yield
        finally:
            self._held = False
            self.close()

    def start(self, worker_id: str, job: WorkerJob) -> _Actor:
        actor = self._actor_cls.options(max_restarts=0, max_task_retries=0, num_cpus=self.num_cpus_per_worker,
                                        num_gpus=self.num_gpus_per_worker).remote(job, worker_id, self.ports)
        return _Actor(actor, actor.ready.remote())

    def submit(self, handle: _Actor, item: EpisodePlan) -> None:
        handle.ref = handle.actor.run.remote(item)

    def wait(self, handles: list[_Actor], timeout: float) -> None:
        import ray

        refs = [r for h in handles if not h.dead
                for r in (h.ready_ref if not h.ready else None, h.ref, h.close_ref) if r is not None]
        if refs:
            ray.wait(refs, num_returns=1, timeout=timeout)

    def events(self, handle: _Actor) -> list[Event]:
        import ray
        from ray.exceptions import RayActorError, RayError

        if handle.dead:
            return []
        out: list[Event] = []
        try:
            if not handle.ready and _done(handle.ready_ref):
                status, payload = ray.get(handle.ready_ref)
                if status == INIT_ERROR:
                    return [(INIT_ERROR, payload)]
                handle.ready, handle.pid = True, payload
                out.append((READY, payload))
            if handle.ref is not None and _done(handle.ref):
                ref, handle.ref = handle.ref, None
                out.append((RESULT, ray.get(ref)))
        except RayActorError as exc:
            out.append(self._dead(handle, f"Ray actor error (pid {handle.pid}: {_short(exc)})"))
        except RayError as exc:
            out.append(self._dead(handle, f"a failure outside the episode ({_short(exc)})"))
        return out

    def _dead(self, handle: _Actor, reason: str) -> Event:
        self.kill(handle)
        return DEAD, reason

    def stop(self, handle: _Actor) -> None:
        if handle.dead:
            return
        if handle.ready and handle.ref is None:
            handle.close_ref = handle.actor.close.remote()  # idle: let it close its recorders
        else:
            self.kill(handle)  # mid-episode or starting: Ray cannot abort the call, end the actor

    def ended(self, handle: _Actor) -> bool:
        if handle.dead:
            return True
        if handle.close_ref is not None and _done(handle.close_ref):
            self.kill(handle)
            return True
        return False

    def kill(self, handle: _Actor) -> None:
        import ray

        if not handle.dead:
            ray.kill(handle.actor, no_restart=True)
            handle.dead = True


def _done(ref: Any) -> bool:
    import ray

    return bool(ray.wait([ref], num_returns=1, timeout=0)[0])


def _short(exc: BaseException) -> str:
    """One line for a Ray error: the task's own exception if there is one, else Ray's first line."""
    cause = getattr(exc, "cause", None)
    text = f"{type(cause).__name__}: {cause}" if isinstance(cause, BaseException) else str(exc)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[0] if lines else type(exc).__name__


class RayExecutor(Supervisor):
    """The supervisor over Ray actors: ``RayExecutor(workers, address=…, timeout_s=…)``."""

    transport: RayTransport

    def __init__(self, workers: int, address: str | None = None, include_dashboard: bool = False,
                 num_cpus_per_worker: float = 1.0, num_gpus_per_worker: float = 0.0, **options: Any) -> None:
        super().__init__(RayTransport(address, include_dashboard, num_cpus_per_worker, num_gpus_per_worker),
                         workers, **options)

    @contextlib.contextmanager
    def served_policy(self, config: RunConfig, workers: int, output_dir: str | Path | None = None,
                      threads: int | None = 1) -> Iterator[dict[str, Any]]:
        """:func:`~molmo_lerobot.serving.run_server.served_policy` on the cluster: with ``policy.serve``
        one server per node (``serve_stats.json`` by node) and each actor routed to its own node's."""
        options = serve_options(config.policy, workers)
        if options is None:
            yield config.policy.given()
            return
        t = self.transport
        with t.held(workers), node_servers(config, options, threads, output_dir, t.num_cpus_per_worker,
                                           t.num_gpus_per_worker) as ports:
            t.ports = ports
            try:
                yield dict(CLIENT_CONFIG)  # the port is each node's (SimulatorActor)
            finally:
                t.ports = None
