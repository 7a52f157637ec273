"""``policy.serve=true``: one local policy server for a whole run, every worker its client.

The policy is loaded once, in a server process of its own, instead of once per worker (GPU
memory once), and requests from the workers are batched (``max_batch`` defaults to the
number of workers). Workers get ``policy=remote`` pointed at it. ``policy.serve_transport``
picks how they talk: ``shm`` (shared memory, :mod:`molmo_lerobot.serving.shm_server`: no
serialisation; workers on this machine only), ``websocket`` (``molmo-serve``'s openpi-compatible
protocol) or ``auto`` (``shm`` for the local executor where the platform has it, else
``websocket``). The server's statistics (transport, requests served, batch sizes seen) are
written to ``<output_dir>/serve_stats.json``. A server whose run has gone (``kill -9`` of
``molmo-eval`` included) stops on its own, as workers do.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot.cpu_threads import cap_threads
from molmo_lerobot.errors import MolmoError
from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.protocol import shm

if TYPE_CHECKING:
    from molmo_lerobot.policies.base import PolicyOptions
    from molmo_lerobot.run_config import RunConfig

STATS_FILE = "serve_stats.json"
#: Seconds a server whose run has gone has to stop gracefully before it exits regardless.
ORPHAN_GRACE_S = 10.0


class ServeError(MolmoError, RuntimeError):
    """The run's policy server could not start."""


def serve_transport(policy: PolicyOptions, executor: str) -> str:
    """``shm`` or ``websocket``: ``policy.serve_transport``, ``auto`` resolved for ``executor``."""
    requested = policy.serve_transport
    if requested == "websocket":
        return requested
    if requested == "shm" and executor != "local":
        raise ServeError(f"policy.serve_transport=shm needs executor=local (workers on the server's machine), "
                         f"not executor={executor}; use serve_transport=websocket or auto")
    if requested == "shm" and not shm.available():
        raise ServeError(f"policy.serve_transport=shm needs Linux (memfd with seals); this is {sys.platform}: "
                         "use serve_transport=websocket or auto")
    if requested not in ("shm", "auto"):
        raise ServeError(f"policy.serve_transport={requested!r}: expected auto, shm or websocket")
    return "shm" if executor == "local" and shm.available() else "websocket"


def serve_options(policy: PolicyOptions, workers: int) -> dict[str, Any] | None:
    """Server options when ``policy`` asks to be served for the run, else None."""
    if not policy.serve:
        return None
    return {"max_batch": int(policy.serve_max_batch or workers),
            "batch_timeout_ms": float(policy.serve_batch_timeout_ms),
            "max_clients": max(8, workers + 2), "first_request_timeout_s": 600.0, "idle_timeout_s": 3600.0}


def _serve(config: RunConfig, transport: str, options: dict[str, Any], threads: int | None,
           conn: Connection) -> None:
    """Server process: rebuild the run's context from its ``config``, build the server, report where
    it listens (or the error), serve until SIGTERM (or its run's end), then send its statistics."""
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.serving.server import PolicyServer, build_server
    from molmo_lerobot.serving.shm_server import ShmPolicyServer

    threading.Thread(target=_exit_when_orphaned, daemon=True).start()
    cap_threads(threads)  # as many as each in-process worker would use: the same rounding
    try:
        cls, where = (ShmPolicyServer, {}) if transport == "shm" else (PolicyServer, {"host": "127.0.0.1", "port": 0})
        server = build_server(RunContext.build(config).plugins, config.policy.given(), cls, **where, **options)
        server.run(ready=lambda srv: conn.send(
            ("ready", srv.address if isinstance(srv, ShmPolicyServer) else srv.port)))
    except BaseException as exc:  # reported to the run, which fails with this line
        with contextlib.suppress(OSError):
            text = str(exc).strip()
            conn.send(("error", f"{type(exc).__name__}: {text.splitlines()[0] if text else ''}"))
        return
    with contextlib.suppress(OSError):
        conn.send(("stats", server.stats()))


def _exit_when_orphaned() -> None:
    """Stop this server gracefully (then for sure) once the run that started it has gone, however
    it went (``kill -9`` included): its parent sentinel, a pipe only the parent holds open, reads
    EOF. A server left behind would hold its model (GPU memory) and the run's resource tracker."""
    parent = mp.parent_process()
    if parent is None:
        raise RuntimeError("a policy server watches the run that started it: run it in a child process")
    wait([parent.sentinel])
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(ORPHAN_GRACE_S)
    os._exit(1)


def _stats(conn: Connection, timeout_s: float) -> dict[str, Any] | None:
    """The statistics the stopping server sends (None if it died without)."""
    with contextlib.suppress(OSError, EOFError):
        while conn.poll(timeout_s):
            kind, value = conn.recv()
            if kind == "stats":
                return value
    return None


@contextlib.contextmanager
def served_policy(config: RunConfig, workers: int, output_dir: str | Path | None = None,
                  start_timeout_s: float = 900.0, threads: int | None = 1) -> Iterator[dict[str, Any]]:
    """Yield the policy config workers should use: the run ``config``'s ``policy`` itself, or
    (``serve: true``) a ``remote`` config for a server process started here (with the context
    rebuilt from ``config``, a portable run config) and stopped (and reaped) on exit.
    The server runs torch/BLAS on ``threads`` CPU threads (the run's ``worker_threads``)."""
    options = serve_options(config.policy, workers)
    if options is None:
        yield config.policy.given()
        return
    transport = serve_transport(config.policy, config.executor.name)
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_serve, args=(config, transport, options, threads, child), name="molmo-serve",
                       daemon=True)
    proc.start()
    child.close()
    started = False
    try:
        deadline = time.monotonic() + start_timeout_s
        while not parent.poll(0.2):
            if not proc.is_alive() or time.monotonic() > deadline:
                why = f"exit code {proc.exitcode}" if not proc.is_alive() else f"not ready after {start_timeout_s:g} s"
                raise ServeError(f"policy.serve: the policy server did not start ({why})")
        try:
            kind, value = parent.recv()
        except EOFError:
            raise ServeError(f"policy.serve: the policy server died while starting "
                             f"(exit code {proc.exitcode})") from None
        if kind != "ready":
            raise ServeError(f"policy.serve: the policy server did not start: {value}")
        started = True
        # a local server refusing connections has died (it never restarts): episodes fail fast
        where = ({"transport": "shm", "socket": value, "connect_timeout_s": 5.0} if transport == "shm"
                 else {"host": "127.0.0.1", "port": value, "connect_timeout_s": 60.0})
        yield {"name": "remote", **where, "timeout_s": 600.0}
    finally:
        proc.terminate()  # SIGTERM: the server closes its connections, sends its statistics and exits
        stats = _stats(parent, 30) if started else None
        if stats is not None and output_dir is not None:
            atomic_write(Path(output_dir, STATS_FILE), json.dumps({**stats, **options}, indent=2) + "\n",
                         root=output_dir)
        proc.join(30)
        if proc.is_alive():
            proc.kill()
            proc.join()
        parent.close()
