"""molmo-serve: serve a policy plugin over the openpi-compatible protocol.

usage: molmo-serve policy=P [host=127.0.0.1] [port=8000] [OPTION=VALUE …] [HYDRA_OVERRIDE …]

Server options (key=value):
  host, port                  where to listen (port=0 picks a free port)
  max_clients=8               connections served at once; a new client evicts one idle >= evict_idle_s
  max_batch=1                 batch requests from different clients (policies with a batched act)
  batch_timeout_ms=20         longest a request waits for due clients to join its batch
  max_concurrency=1           policy calls run at once without batching
  max_message_bytes=67108864  largest request or reply
  first_request_timeout_s=10  a connection must send its first request within this
  idle_timeout_s=120          a connection is closed after this long without a request
  evict_idle_s=2              connections idle this long may be evicted when the server is full

Every other argument is a Hydra override of the eval config (policy=lerobot policy.path=…
policy.device=cuda). Clients: molmo-eval policy=remote policy.host=… policy.port=… (any
policy, native observations). Privileged scripted experts need the simulator and are refused.
"""

from __future__ import annotations

import logging
import sys
from typing import TYPE_CHECKING, Any

from molmo_lerobot.errors import MolmoError

if TYPE_CHECKING:
    from molmo_lerobot.serving.server import PolicyServer

SERVER_OPTIONS = {
    "host": str,
    "port": int,
    "max_clients": int,
    "max_batch": int,
    "batch_timeout_ms": float,
    "max_concurrency": int,
    "max_message_bytes": int,
    "first_request_timeout_s": float,
    "idle_timeout_s": float,
    "evict_idle_s": float,
}


class _Usage(MolmoError):
    pass


def parse_args(argv: list[str]) -> tuple[dict[str, Any], list[str]]:
    """Split ``argv`` into server options and Hydra overrides."""
    options: dict[str, Any] = {"host": "127.0.0.1", "port": 8000}
    overrides = []
    for arg in argv:
        key, sep, value = arg.partition("=")
        if sep and key in SERVER_OPTIONS:
            try:
                options[key] = SERVER_OPTIONS[key](value)
            except ValueError:
                kind = SERVER_OPTIONS[key].__name__
                raise SystemExit(f"molmo-serve: {key}={value!r} is not a valid {kind}") from None
        elif arg in ("-h", "--help"):
            raise _Usage
        else:
            overrides.append(arg)
    return options, overrides


def main(argv: list[str] | None = None) -> int:
    from molmo_lerobot.config import ConfigError, compose
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.serving.server import PolicyNotServable, build_server

    try:
        options, overrides = parse_args(sys.argv[1:] if argv is None else argv)
    except _Usage:
        print(__doc__.strip())
        return 0
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        run = RunContext.build(compose(overrides))
        name = run.config.policy.name
        server = build_server(run.plugins, run.config.policy.given(), **options)
    except (ConfigError, LookupError, ValueError, FileNotFoundError, ImportError) as exc:  # PluginError, AssetError
        print(f"molmo-serve: {exc}", file=sys.stderr)
        return 2

    def ready(srv: PolicyServer) -> None:
        print(f"molmo-serve: serving policy {name!r} on ws://{srv.host}:{srv.port}"
              + (f" (batches of up to {srv.max_batch})" if srv.batching else ""), flush=True)

    try:
        server.run(ready=ready)
    except (PolicyNotServable, ConfigError, PluginError, ValueError, FileNotFoundError, ImportError) as exc:
        print(f"molmo-serve: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
