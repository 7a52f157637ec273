"""``executor=ray policy.serve=true``: one policy server per Ray node, each node's workers its clients.

On a cluster one server for the whole run would pull every camera frame across the network
to one machine. Instead every node that can host a simulator actor gets a
:class:`PolicyServerActor`: a Ray actor pinned to that node (node-affinity scheduling, not
soft), holding one of its GPUs when it has any (``num_gpus=1``; Ray then sets
``CUDA_VISIBLE_DEVICES`` for it), else reserving no resources, and running the same server as
``molmo-serve`` (:func:`~molmo_lerobot.serving.server.build_server`) on a thread, bound to
the node's loopback interface. :func:`node_servers` yields the route table (node id → port);
each simulator actor looks up its own node's port, so observations and actions never leave
the node and requests of the workers of one node are batched together.

A server that dies (its process killed, its node lost) drops its clients' connections: their
running episodes fail with a connection error, and the episodes that node's workers start
afterwards cannot connect; both are infrastructure errors, which ``resume=true`` runs again.
``serve_stats.json`` holds every server's statistics by node, and their totals.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot.cpu_threads import cap_threads
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.serving.run_server import STATS_FILE, ServeError

if TYPE_CHECKING:
    from molmo_lerobot.run_config import RunConfig

#: what each worker's ``policy=remote`` gets besides its node's port
CLIENT_CONFIG = {"name": "remote", "host": "127.0.0.1", "timeout_s": 600.0, "connect_timeout_s": 15.0}


class PolicyServerActor:
    """Body of one node's Ray actor: the run's policy behind :func:`build_server`, served on a thread."""

    def __init__(self, config: RunConfig, options: dict[str, Any], threads: int | None,
                 start_timeout_s: float) -> None:
        import ray

        from molmo_lerobot.context import RunContext
        from molmo_lerobot.serving.server import build_server, serve_in_thread

        self.node_id = ray.get_runtime_context().get_node_id()
        self.gpu_ids = [str(g) for g in ray.get_gpu_ids()]
        self._stack = contextlib.ExitStack()
        self.server: Any = None
        self.error: str | None = None
        cap_threads(threads)
        try:
            server = build_server(RunContext.build(config).plugins, config.policy.given(), host="127.0.0.1", port=0,
                                  **options)
            self.server = self._stack.enter_context(serve_in_thread(server, start_timeout_s))
        except Exception as exc:  # reported by address(): the run fails with this line
            text = str(exc).strip()
            self.error = f"{type(exc).__name__}: {text.splitlines()[0] if text else ''}"

    def address(self) -> tuple[str, int | str]:
        """``("ready", port)`` or ``("error", why)``."""
        if self.server is None:
            return "error", self.error or "the policy server did not start"
        return "ready", int(self.server.port)

    def stats(self) -> dict[str, Any]:
        return {**self.server.stats(), "gpu_ids": self.gpu_ids}

    def stop(self) -> None:
        """Close the clients' connections and the policy; the actor is killed afterwards."""
        self._stack.close()


@dataclass
class NodeServer:
    """One node's server as the driver sees it."""

    node_id: str
    node_ip: str
    num_gpus: int
    actor: Any
    port: int | None = None


def server_nodes(nodes: list[dict[str, Any]], num_cpus_per_worker: float,
                 num_gpus_per_worker: float) -> list[dict[str, Any]]:
    """The alive nodes of ``ray.nodes()`` with room for at least one simulator actor."""
    return [n for n in nodes if n.get("Alive")
            and n["Resources"].get("CPU", 0.0) >= num_cpus_per_worker
            and n["Resources"].get("GPU", 0.0) >= num_gpus_per_worker]


def _start(config: RunConfig, options: dict[str, Any], threads: int | None, node: dict[str, Any],
           start_timeout_s: float) -> NodeServer:
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    gpus = 1 if node["Resources"].get("GPU", 0.0) >= 1 else 0
    actor = ray.remote(PolicyServerActor).options(
        num_cpus=0, num_gpus=gpus, max_restarts=0, max_concurrency=2,  # stats() while a stop() runs
        scheduling_strategy=NodeAffinitySchedulingStrategy(node["NodeID"], soft=False),
    ).remote(config, options, threads, start_timeout_s)
    return NodeServer(node["NodeID"], node.get("NodeManagerAddress", "?"), gpus, actor)


@contextlib.contextmanager
def node_servers(config: RunConfig, options: dict[str, Any], threads: int | None = 1,
                 output_dir: str | Path | None = None, num_cpus_per_worker: float = 1.0,
                 num_gpus_per_worker: float = 0.0, start_timeout_s: float = 900.0) -> Iterator[dict[str, int]]:
    """Start one server per node of the connected Ray cluster that can host a simulator actor and
    yield their ports by node id; on exit write ``serve_stats.json`` and end every server."""
    import ray

    nodes = server_nodes(ray.nodes(), num_cpus_per_worker, num_gpus_per_worker)
    if not nodes:
        raise ServeError(f"policy.serve: no alive Ray node has room for a simulator actor "
                         f"({num_cpus_per_worker:g} CPU, {num_gpus_per_worker:g} GPU)")
    servers = [_start(config, options, threads, node, start_timeout_s) for node in nodes]
    try:
        _wait_ready(servers, start_timeout_s)
        yield {s.node_id: s.port for s in servers if s.port is not None}
    finally:
        stats = _collect(servers)
        if output_dir is not None and any(s.port is not None for s in servers):
            atomic_write(Path(output_dir, STATS_FILE), json.dumps({**stats, **options}, indent=2) + "\n",
                         root=output_dir)
        for s in servers:
            with contextlib.suppress(Exception):
                ray.get(s.actor.stop.remote(), timeout=30)
            ray.kill(s.actor, no_restart=True)


def _wait_ready(servers: list[NodeServer], start_timeout_s: float) -> None:
    import ray
    from ray.exceptions import GetTimeoutError, RayError

    deadline = time.monotonic() + start_timeout_s
    for s in servers:
        where = f"the policy server on node {s.node_id[:12]} ({s.node_ip})"
        try:
            kind, value = ray.get(s.actor.address.remote(), timeout=max(0.0, deadline - time.monotonic()))
        except GetTimeoutError:
            raise ServeError(f"policy.serve: {where} did not start within {start_timeout_s:g} s") from None
        except RayError as exc:
            raise ServeError(f"policy.serve: {where} died while starting: {_first_line(exc)}") from None
        if kind != "ready":
            raise ServeError(f"policy.serve: {where} did not start: {value}")
        s.port = int(value)


def _collect(servers: list[NodeServer]) -> dict[str, Any]:
    """Each server's statistics by node id (``alive: false`` for one that died) and their totals."""
    import ray
    from ray.exceptions import GetTimeoutError, RayError

    by_node: dict[str, Any] = {}
    sizes: Counter[int] = Counter()
    for s in servers:
        if s.port is None:
            continue
        entry: dict[str, Any] = {"node_ip": s.node_ip, "port": s.port, "num_gpus": s.num_gpus}
        try:
            entry |= ray.get(s.actor.stats.remote(), timeout=10) | {"alive": True}
        except (RayError, GetTimeoutError) as exc:
            entry |= {"alive": False, "error": _first_line(exc)}
        sizes.update({int(k): v for k, v in entry.get("batch_sizes", {}).items()})
        by_node[s.node_id] = entry
    return {"served": sum(e.get("served", 0) for e in by_node.values()),
            "batching": any(e.get("batching") for e in by_node.values()),
            "batch_sizes": {str(k): v for k, v in sorted(sizes.items())},
            "servers": len(by_node), "servers_died": sum(not e["alive"] for e in by_node.values()),
            "nodes": by_node}


def _first_line(exc: BaseException) -> str:
    cause = getattr(exc, "cause", None)
    text = f"{type(cause).__name__}: {cause}" if isinstance(cause, BaseException) else str(exc)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[0] if lines else type(exc).__name__
