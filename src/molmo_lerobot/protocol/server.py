"""Serve any :class:`~molmo_lerobot.policies.base.Policy` over the openpi-compatible protocol.

Each connection gets its own policy instance (per-client state: a stateful policy is never
shared between clients). On connect the server sends a metadata dict, then answers every
binary msgpack observation with an action dict plus ``server_timing``. ``{"endpoint":
"reset", ...}`` resets the connection's policy; without it the policy is reset before its
first observation. ``GET /healthz`` answers 200.

A malformed, oversized or failing request gets a **text** frame with the reason (a traceback
for policy errors, as openpi does) and a close with code 1011, for that client only; the
server keeps serving the others. Frames over twice the size limit are cut off by the
websocket layer itself (close code 1009) before they are read into memory.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from http import HTTPStatus
from typing import Any

import numpy as np
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode
from websockets.http11 import Request, Response

from molmo_lerobot.policies.base import EpisodeContext, Policy
from molmo_lerobot.protocol.client import RESET_ENDPOINT
from molmo_lerobot.protocol.codec import CodecError, packb, unpackb

log = logging.getLogger(__name__)

DEFAULT_MOVE_GROUPS = {"arm": 7, "gripper": 1}


class RequestError(ValueError):
    """A client's request cannot be served (the message is sent back to it)."""


class PolicyServer:
    """An asyncio websocket server; ``factory()`` builds one policy per connection."""

    def __init__(
        self,
        factory: Callable[[], Policy],
        *,
        host: str = "127.0.0.1",
        port: int = 8000,
        metadata: dict[str, Any] | None = None,
        max_clients: int = 8,
        max_concurrency: int = 1,
        max_message_bytes: int = 64 * 2**20,
        recv_timeout_s: float = 600.0,
        shutdown_timeout_s: float = 30.0,
    ) -> None:
        self.factory = factory
        self.host, self.port = host, port
        self.metadata = dict(metadata or {})
        self.max_clients = max_clients
        self.max_concurrency = max_concurrency
        self.max_message_bytes = max_message_bytes
        self.recv_timeout_s = recv_timeout_s
        self.shutdown_timeout_s = shutdown_timeout_s
        self.active = 0
        self.served = 0
        self._pool = ThreadPoolExecutor(max_workers=max_clients + 1, thread_name_prefix="policy")
        self._infer_slots: asyncio.Semaphore | None = None
        self._server: Server | None = None
        self._stop: asyncio.Event | None = None

    # lifecycle ---------------------------------------------------------------------------
    async def serve(self, ready: Callable[[PolicyServer], None] | None = None) -> None:
        """Serve until :meth:`request_stop`; then close connections (1001) and policies."""
        self._infer_slots = asyncio.Semaphore(self.max_concurrency)
        self._stop = asyncio.Event()
        server = await serve(
            self._handle,
            self.host,
            self.port,
            compression=None,
            max_size=2 * self.max_message_bytes,
            ping_interval=None,
            process_request=self._process_request,
        )
        self._server = server
        self.port = server.sockets[0].getsockname()[1]
        log.info("serving policy on ws://%s:%d", self.host, self.port)
        if ready is not None:
            ready(self)
        await self._stop.wait()
        log.info("shutting down: closing %d connection(s)", self.active)
        server.close()  # stop accepting; close connections with 1001 (going away)
        try:
            await asyncio.wait_for(server.wait_closed(), self.shutdown_timeout_s)
            self._pool.shutdown(wait=True)
        except TimeoutError:
            log.warning("policy calls still running after %g s; not waiting for them", self.shutdown_timeout_s)
            self._pool.shutdown(wait=False, cancel_futures=True)

    def request_stop(self) -> None:
        """Ask :meth:`serve` to shut down (call from the event loop thread)."""
        if self._stop is not None:
            self._stop.set()

    def run(self, ready: Callable[[PolicyServer], None] | None = None) -> None:
        """Serve in the foreground; SIGINT/SIGTERM shut down gracefully."""

        async def main() -> None:
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, self.request_stop)
            await self.serve(ready=ready)

        asyncio.run(main())

    # websocket handling ------------------------------------------------------------------
    def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        if request.path == "/healthz":
            return connection.respond(HTTPStatus.OK, "OK\n")
        if self.active >= self.max_clients:
            return connection.respond(HTTPStatus.SERVICE_UNAVAILABLE, f"server busy ({self.max_clients} clients)\n")
        return None

    async def _call(self, fn: Callable, *args: Any) -> Any:
        return await asyncio.get_running_loop().run_in_executor(self._pool, fn, *args)

    async def _handle(self, ws: ServerConnection) -> None:
        self.active += 1
        policy: Policy | None = None
        peer = ws.remote_address
        try:
            try:
                policy = await self._call(self.factory)
            except Exception:
                await _fail(ws, traceback.format_exc())
                return
            await ws.send(packb(self.metadata))
            await self._session(ws, policy)
        except ConnectionClosed:
            pass
        finally:
            self.active -= 1
            if policy is not None:
                with contextlib.suppress(Exception):
                    await self._call(policy.close)
            log.debug("client %s gone", peer)

    async def _session(self, ws: ServerConnection, policy: Policy) -> None:
        needs_reset = True
        prev_total_ms = None
        while True:
            try:
                frame = await asyncio.wait_for(ws.recv(), self.recv_timeout_s)
            except TimeoutError:
                await ws.close(CloseCode.GOING_AWAY, f"no request for {self.recv_timeout_s:g} s")
                return
            start = time.perf_counter()
            try:
                request = self._decode(frame)
            except RequestError as exc:
                await _fail(ws, f"RequestError: {exc}")
                return
            try:
                if request.get("endpoint") == RESET_ENDPOINT:
                    await self._call(policy.reset, _context(request))
                    needs_reset = False
                    await ws.send(packb({"endpoint": RESET_ENDPOINT, "ok": True}))
                    continue
                if needs_reset:
                    await self._call(policy.reset, _context(request))
                    needs_reset = False
                async with self._infer_slots:
                    t0 = time.perf_counter()
                    action = await self._call(policy.act, request)
                    infer_ms = 1000 * (time.perf_counter() - t0)
                response = _response(action)
                response["server_timing"] = {"infer_ms": infer_ms}
                if prev_total_ms is not None:
                    response["server_timing"]["prev_total_ms"] = prev_total_ms
                payload = packb(response)
            except ConnectionClosed:
                raise
            except Exception:
                await _fail(ws, traceback.format_exc())
                return
            await ws.send(payload)
            self.served += 1
            prev_total_ms = 1000 * (time.perf_counter() - start)

    def _decode(self, frame: str | bytes) -> dict[str, Any]:
        if isinstance(frame, str):
            raise RequestError("expected a binary msgpack frame, got a text frame")
        if len(frame) > self.max_message_bytes:
            raise RequestError(f"message of {len(frame)} bytes exceeds the limit of {self.max_message_bytes} bytes")
        try:
            request = unpackb(frame)
        except CodecError as exc:
            raise RequestError(str(exc)) from None
        if not isinstance(request, dict):
            raise RequestError(f"request must be a msgpack map, got {type(request).__name__}")
        return request


async def _fail(ws: ServerConnection, message: str) -> None:
    """openpi's error convention: the reason as a text frame, then close 1011."""
    log.warning("closing client %s: %s", ws.remote_address, message.strip().splitlines()[-1])
    with contextlib.suppress(ConnectionClosed):
        await ws.send(message)
        await ws.close(CloseCode.INTERNAL_ERROR, "request failed; reason in the previous frame")


def _context(request: dict[str, Any]) -> EpisodeContext:
    """An episode context from a reset message (or the first observation): no privileged state."""
    known = {"endpoint", "episode_index", "seed", "prompt", "move_groups", "policy_dt_s"}
    prompt = request.get("prompt", "")
    return EpisodeContext(
        spec=None,  # type: ignore[arg-type]  # remote clients never share their episode spec
        episode_index=int(request.get("episode_index", -1)),
        seed=int(request.get("seed", 0)),
        prompt=prompt if isinstance(prompt, str) else "",
        move_groups=dict(request.get("move_groups") or DEFAULT_MOVE_GROUPS),
        policy_dt_s=float(request.get("policy_dt_s", 0.066)),
        extra={k: v for k, v in request.items() if k not in known} if request.get("endpoint") == RESET_ENDPOINT else {},
    )


def _response(action: Any) -> dict[str, Any]:
    if not isinstance(action, dict):
        raise TypeError(f"policy returned {type(action).__name__}, expected a dict of arrays")
    return {str(k): (np.asarray(v) if isinstance(v, (list, tuple)) else v) for k, v in action.items()}


@contextlib.contextmanager
def serve_in_thread(server: PolicyServer, start_timeout_s: float = 30.0) -> Iterator[PolicyServer]:
    """Run ``server`` on a background event loop (tests, benchmarks); stop it on exit."""
    ready = threading.Event()
    errors: list[BaseException] = []
    loop = asyncio.new_event_loop()

    def main() -> None:
        try:
            loop.run_until_complete(server.serve(ready=lambda _: ready.set()))
        except BaseException as exc:  # surfaced to the caller below
            errors.append(exc)
            ready.set()
        finally:
            loop.close()

    thread = threading.Thread(target=main, name="policy-server", daemon=True)
    thread.start()
    if not ready.wait(start_timeout_s) or errors:
        raise RuntimeError(f"policy server did not start: {errors[0] if errors else 'timeout'}")
    try:
        yield server
    finally:
        loop.call_soon_threadsafe(server.request_stop)
        thread.join(timeout=30)
