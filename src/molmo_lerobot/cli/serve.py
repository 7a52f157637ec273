"""``molmo-serve policy=P [host=127.0.0.1] [port=8000] [max_clients=8] …``: serve a policy plugin.

Speaks the openpi-compatible protocol (see :mod:`molmo_lerobot.protocol.server`). Server
options are ``key=value`` arguments; every other argument is a Hydra override of the eval
config (``policy=lerobot policy.path=… policy.device=cuda``).
"""

from __future__ import annotations

import logging
import sys
import threading
from typing import Any

from omegaconf import OmegaConf

SERVER_OPTIONS = {
    "host": str,
    "port": int,
    "max_clients": int,
    "max_concurrency": int,
    "max_message_bytes": int,
    "recv_timeout_s": float,
}


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
                raise SystemExit(f"molmo-serve: {key}={value!r} is not a valid {SERVER_OPTIONS[key].__name__}") from None
        elif arg in ("-h", "--help"):
            raise SystemExit(__doc__)
        else:
            overrides.append(arg)
    return options, overrides


class _FirstThenFresh:
    """Policy factory: hands out the instance built at start-up (to fail fast), then new ones."""

    def __init__(self, policy_cfg: dict[str, Any]) -> None:
        from molmo_lerobot.runner.policy import make_policy

        self._make = make_policy
        self._cfg = policy_cfg
        self._first = make_policy(policy_cfg)
        self._lock = threading.Lock()

    def __call__(self):
        with self._lock:
            first, self._first = self._first, None
        return first if first is not None else self._make(self._cfg)


def main(argv: list[str] | None = None) -> int:
    from molmo_lerobot import __version__
    from molmo_lerobot.config import ConfigError, compose
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.protocol.server import PolicyServer

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    options, overrides = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        cfg = compose(overrides)
        policy_cfg = OmegaConf.to_container(cfg.policy, resolve=True)
        factory = _FirstThenFresh(policy_cfg)  # type: ignore[arg-type]
    except (ConfigError, PluginError, ValueError, FileNotFoundError, ImportError) as exc:
        print(f"molmo-serve: {exc}", file=sys.stderr)
        return 2
    metadata = {"server": "molmo-serve", "version": __version__, "policy": policy_cfg.get("name")}
    server = PolicyServer(factory, metadata=metadata, **options)

    def ready(srv: PolicyServer) -> None:
        print(f"molmo-serve: serving policy {policy_cfg.get('name')!r} on ws://{srv.host}:{srv.port}", flush=True)

    server.run(ready=ready)
    return 0


if __name__ == "__main__":
    sys.exit(main())
