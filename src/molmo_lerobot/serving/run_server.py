"""``policy.serve=true``: one local ``molmo-serve`` for a whole run, every worker its client.

The policy is loaded once, in a server process of its own, instead of once per worker (GPU
memory once), and requests from the workers are batched (``max_batch`` defaults to the
number of workers). Workers get ``policy=remote`` pointed at it. The server's statistics
(requests served, batch sizes seen) are written to ``<output_dir>/serve_stats.json``.
"""

from __future__ import annotations

import contextlib
import http.client
import json
import multiprocessing as mp
import time
from collections.abc import Iterator
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from molmo_lerobot.cpu_threads import cap_threads
from molmo_lerobot.errors import MolmoError
from molmo_lerobot.fileio import atomic_write

STATS_FILE = "serve_stats.json"


class ServeError(MolmoError, RuntimeError):
    """The run's policy server could not start."""


def serve_options(policy_cfg: dict[str, Any], workers: int) -> dict[str, Any] | None:
    """Server options when ``policy_cfg`` asks to be served for the run, else None."""
    if not policy_cfg.get("serve"):
        return None
    return {"max_batch": int(policy_cfg.get("serve_max_batch") or workers),
            "batch_timeout_ms": float(policy_cfg.get("serve_batch_timeout_ms", 50.0)),
            "max_clients": max(8, workers + 2), "first_request_timeout_s": 600.0, "idle_timeout_s": 3600.0}


def _serve(config: dict[str, Any], options: dict[str, Any], threads: int | None, conn: Connection) -> None:
    """Server process: rebuild the run's context from its ``config``, build the server, report its
    port (or the error), serve until SIGTERM."""
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.serving.server import build_server

    cap_threads(threads)  # as many as each in-process worker would use: the same rounding
    try:
        server = build_server(RunContext.build(config).plugins, config["policy"], host="127.0.0.1", port=0, **options)
        server.run(ready=lambda srv: conn.send(("ready", srv.port)))
    except BaseException as exc:  # reported to the run, which fails with this line
        with contextlib.suppress(OSError):
            text = str(exc).strip()
            conn.send(("error", f"{type(exc).__name__}: {text.splitlines()[0] if text else ''}"))


def fetch_stats(port: int) -> dict[str, Any] | None:
    with contextlib.suppress(OSError, ValueError, http.client.HTTPException):
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
        conn.request("GET", "/stats")
        return json.loads(conn.getresponse().read())
    return None


@contextlib.contextmanager
def served_policy(config: dict[str, Any], workers: int, output_dir: str | Path | None = None,
                  start_timeout_s: float = 900.0, threads: int | None = 1) -> Iterator[dict[str, Any]]:
    """Yield the policy config workers should use: the run ``config``'s ``policy`` itself, or
    (``serve: true``) a ``remote`` config for a server process started here (with the context
    rebuilt from ``config``, a portable run config) and stopped (and reaped) on exit.
    The server runs torch/BLAS on ``threads`` CPU threads (the run's ``worker_threads``)."""
    policy_cfg = config["policy"]
    options = serve_options(policy_cfg, workers)
    if options is None:
        yield policy_cfg
        return
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_serve, args=(config, options, threads, child), name="molmo-serve", daemon=True)
    proc.start()
    child.close()
    port = None
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
        port = int(value)
        yield {"name": "remote", "host": "127.0.0.1", "port": port, "timeout_s": 600.0, "connect_timeout_s": 60.0}
    finally:
        stats = fetch_stats(port) if port is not None else None
        if stats is not None and output_dir is not None:
            atomic_write(Path(output_dir, STATS_FILE), json.dumps({**stats, **options}, indent=2) + "\n",
                         root=output_dir)
        proc.terminate()  # SIGTERM: the server closes its connections and exits
        proc.join(30)
        if proc.is_alive():
            proc.kill()
            proc.join()
        parent.close()
