"""Serve any :class:`~molmo_lerobot.policies.base.Policy` over the openpi-compatible protocol.

Each connection gets its own policy instance (per-client state: a stateful policy is never
shared between clients): a :meth:`~molmo_lerobot.policies.base.Policy.fork` of the policy
built at start-up when it can share its model, else a fresh instance. On connect the server
sends a metadata dict, then answers every binary msgpack observation (the native format of
:mod:`molmo_lerobot.serving.native`) with an action dict plus ``server_timing``.
``{"endpoint": "reset", ...}`` resets the connection's policy; without it the policy is reset
before its first observation. ``GET /healthz`` answers 200, ``GET /stats`` a JSON summary
(requests served, the batch sizes seen, evictions).

**Batching.** With ``max_batch > 1`` and a policy whose ``batched`` is true, requests from
different connections that arrive within ``batch_timeout_ms`` of the first (up to
``max_batch``) run as one ``act_batch`` call. A batch is sent as soon as no other client is
due: clients idle for longer than their usual cycle between requests (building a scene,
say) are not waited for, and clients in step wait for each other, so they stay in step.
Each client keeps its own policy state; an item that fails fails only its own request.

**Bounds.** Everything a client can ask for is bounded: the message size (in both directions,
checked before a reply is encoded), move groups, images, arrays and numbers (see
:mod:`~molmo_lerobot.serving.native`), frames buffered per connection, and time: a
connection must send its first request within ``first_request_timeout_s`` and is closed after
``idle_timeout_s`` without one. When all ``max_clients`` slots are taken, a new client evicts
the connection idle the longest (at least ``evict_idle_s``; close code 1001, which our client
treats as a reconnectable drop), so idle connections never lock active clients out.

A malformed, oversized or failing request gets a **text** frame with the reason (a traceback
for policy errors, as openpi does) and a close with code 1011, for that client only; the
server keeps serving the others.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import signal
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from http import HTTPStatus
from typing import TYPE_CHECKING, Any

import numpy as np
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode
from websockets.http11 import Request, Response

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.policies.base import Action, Policy
from molmo_lerobot.protocol.client import RESET_ENDPOINT
from molmo_lerobot.protocol.codec import CodecError, packb, unpackb
from molmo_lerobot.serving.native import RequestError, action_nbytes, check_observation, episode_context

if TYPE_CHECKING:
    from molmo_lerobot.plugins import Plugins

log = logging.getLogger(__name__)

__all__ = ["PolicyNotServable", "PolicyServer", "RequestError", "serve_in_thread"]


class PolicyNotServable(MolmoError, ValueError):
    """The policy cannot run in a server (it needs the simulator)."""


@dataclass(eq=False)
class _Client:
    ws: Any  # the connection (a websocket, or a socket of a subclass's transport)
    since: float = field(default_factory=time.monotonic)  # last activity (connect or a finished request)
    policy: Policy | None = None
    busy: bool = False
    evicted: bool = False
    cycle: float | None = None  # the client's usual time between an answer and its next request
    acting: bool = False  # its last request was an observation (not a reset)
    queued: bool = False  # its observation waits in the batch queue
    needs_reset: bool = True  # its policy is reset before its first observation unless asked first

    def expected(self, now: float, batch_timeout_s: float) -> bool:
        """Whether this client's next observation is due soon: worth holding a batch open for."""
        if self.queued or self.evicted or self.policy is None:
            return False
        window = 1.0 if self.cycle is None else 1.5 * self.cycle + batch_timeout_s
        return self.busy or now - self.since < window


@dataclass(eq=False)
class _Pending:
    policy: Policy
    obs: dict[str, Any]
    future: asyncio.Future
    t: float = field(default_factory=time.monotonic)


class PolicyServer:
    """An asyncio websocket server for the policies ``factory()`` builds (see the module docstring)."""

    transport = "websocket"

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
        first_request_timeout_s: float = 10.0,
        idle_timeout_s: float = 120.0,
        evict_idle_s: float = 2.0,
        max_batch: int = 1,
        batch_timeout_ms: float = 20.0,
        shutdown_timeout_s: float = 30.0,
    ) -> None:
        for name, value in (("max_clients", max_clients), ("max_concurrency", max_concurrency),
                            ("max_message_bytes", max_message_bytes), ("max_batch", max_batch)):
            if value < 1:
                raise ValueError(f"{name} must be at least 1, got {value}")
        for name, seconds in (("first_request_timeout_s", first_request_timeout_s),
                              ("idle_timeout_s", idle_timeout_s), ("evict_idle_s", evict_idle_s),
                              ("batch_timeout_ms", batch_timeout_ms)):
            if not seconds >= 0:
                raise ValueError(f"{name} must be >= 0, got {seconds}")
        self.factory = factory
        self.host, self.port = host, port
        self.metadata = dict(metadata or {})
        self.max_clients = max_clients
        self.max_concurrency = max_concurrency
        self.max_message_bytes = max_message_bytes
        self.first_request_timeout_s = first_request_timeout_s
        self.idle_timeout_s = idle_timeout_s
        self.evict_idle_s = evict_idle_s
        self.max_batch = max_batch
        self.batch_timeout_s = batch_timeout_ms / 1000.0
        self.shutdown_timeout_s = shutdown_timeout_s
        self.served = 0
        self.evictions = 0
        self.batch_sizes: Counter[int] = Counter()
        self.batching = False
        self._clients: set[_Client] = set()
        self._pool = ThreadPoolExecutor(max_workers=max_clients + 2, thread_name_prefix="policy")
        self._proto: Policy | None = None
        self._proto_handed_out = False
        self._infer_slots: asyncio.Semaphore | None = None
        self._pending: list[_Pending] = []
        self._wake: asyncio.Event | None = None
        self._server: Server | None = None  # the websocket listener
        self._stop: asyncio.Event | None = None

    @property
    def active(self) -> int:
        """Connected clients (evicted ones excluded)."""
        return sum(not c.evicted for c in self._clients)

    def stats(self) -> dict[str, Any]:
        return {"transport": self.transport, "served": self.served, "active": self.active, "evictions": self.evictions,
                "batching": self.batching, "max_batch": self.max_batch,
                "batch_sizes": {str(k): v for k, v in sorted(self.batch_sizes.items())}}

    # lifecycle ---------------------------------------------------------------------------
    async def serve(self, ready: Callable[[PolicyServer], None] | None = None) -> None:
        """Build the policy (fail fast), serve until :meth:`request_stop`, then close everything."""
        self._proto = await self._call(self.factory)
        if getattr(self._proto, "needs_simulator", False):
            with contextlib.suppress(Exception):
                self._proto.close()
            name = self.metadata.get("policy") or type(self._proto).__name__
            raise PolicyNotServable(f"policy {name!r} reads the simulator (a privileged scripted expert) and cannot be "
                                    "served; run it in the evaluation process instead (molmo-eval policy=…)")
        self.batching = self.max_batch > 1 and bool(getattr(self._proto, "batched", False))
        self.metadata.setdefault("needs_images", bool(getattr(self._proto, "needs_images", True)))
        self.metadata.setdefault("needs_environment_state", bool(getattr(self._proto, "needs_environment_state",
                                                                         False)))
        self.metadata.setdefault("batched", self.batching)
        self._infer_slots = asyncio.Semaphore(self.max_concurrency)
        self._stop = asyncio.Event()
        self._wake = asyncio.Event()
        batcher = asyncio.create_task(self._batcher()) if self.batching else None
        await self._open()
        log.info("serving policy on %s%s", self.endpoint,
                 f" (batches of up to {self.max_batch})" if self.batching else "")
        if ready is not None:
            ready(self)
        await self._stop.wait()
        log.info("shutting down: closing %d connection(s)", self.active)
        try:
            await asyncio.wait_for(self._shut(), self.shutdown_timeout_s)
            if batcher is not None:
                batcher.cancel()
            if not self._proto_handed_out:
                await self._call(self._proto.close)
            self._pool.shutdown(wait=True)
        except TimeoutError:
            log.warning("policy calls still running after %g s; not waiting for them", self.shutdown_timeout_s)
            self._pool.shutdown(wait=False, cancel_futures=True)

    @property
    def endpoint(self) -> str:
        """Where clients connect."""
        return f"ws://{self.host}:{self.port}"

    async def _open(self) -> None:
        """Start accepting connections."""
        self._server = await serve(self._handle, self.host, self.port, compression=None,
                                   max_size=2 * self.max_message_bytes, max_queue=2, ping_interval=None,
                                   process_request=self._process_request)
        self.port = self._server.sockets[0].getsockname()[1]

    async def _shut(self) -> None:
        """Stop accepting; close the connections (1001, going away) and wait for their handlers."""
        assert self._server is not None
        self._server.close()
        await self._server.wait_closed()

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

    # connections -------------------------------------------------------------------------
    def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        if request.path == "/healthz":
            return connection.respond(HTTPStatus.OK, "OK\n")
        if request.path == "/stats":
            return connection.respond(HTTPStatus.OK, json.dumps(self.stats()) + "\n")
        if self.active >= self.max_clients and not self._evict_idlest():
            return connection.respond(HTTPStatus.SERVICE_UNAVAILABLE, f"server busy ({self.max_clients} clients)\n")
        return None

    def _evict_idlest(self) -> bool:
        """Close the connection idle the longest (at least ``evict_idle_s``) to make room."""
        now = time.monotonic()
        idle = [c for c in self._clients if not c.busy and not c.evicted and now - c.since >= self.evict_idle_s]
        if not idle:
            return False
        victim = min(idle, key=lambda c: c.since)
        victim.evicted = True
        self.evictions += 1
        log.info("evicting client %s, idle for %.1f s, for a new client", victim.ws.remote_address, now - victim.since)
        asyncio.get_running_loop().create_task(
            victim.ws.close(CloseCode.GOING_AWAY, f"idle for {now - victim.since:.0f} s while the server was full"))
        return True

    def _new_policy(self) -> Policy:
        assert self._proto is not None
        fork = self._proto.fork()
        if fork is not None:
            return fork
        if not self._proto_handed_out:
            self._proto_handed_out = True
            return self._proto
        return self.factory()

    async def _call(self, fn: Callable, *args: Any) -> Any:
        return await asyncio.get_running_loop().run_in_executor(self._pool, fn, *args)

    async def _handle(self, ws: ServerConnection) -> None:
        client = _Client(ws)
        self._clients.add(client)
        try:
            if self.active > self.max_clients:  # lost a race with another new client
                await ws.close(CloseCode.TRY_AGAIN_LATER, f"server busy ({self.max_clients} clients)")
                return
            try:
                client.policy = await self._call(self._new_policy)
            except Exception:
                await _fail(ws, traceback.format_exc())
                return
            await ws.send(packb(self.metadata))
            client.since = time.monotonic()
            await self._session(client)
        except ConnectionClosed:
            pass
        finally:
            self._clients.discard(client)
            if client.policy is not None:
                with contextlib.suppress(Exception):
                    await self._call(client.policy.close)
            log.debug("client %s gone", ws.remote_address)

    async def _session(self, client: _Client) -> None:
        ws = client.ws
        timeout = self.first_request_timeout_s
        prev_total_ms = None
        while True:
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout)
            except TimeoutError:
                await ws.close(CloseCode.GOING_AWAY, f"no request for {timeout:g} s")
                return
            timeout = self.idle_timeout_s
            client.busy = True
            start = time.perf_counter()
            gap = time.monotonic() - client.since
            try:
                answer = await self._answer(client, self._decode(frame), gap)
                if answer is None:
                    await ws.send(packb({"endpoint": RESET_ENDPOINT, "ok": True}))
                    continue
                payload = self._encode(*answer, prev_total_ms)
            except ConnectionClosed:
                raise
            except RequestError as exc:
                await _fail(ws, f"RequestError: {exc}")
                return
            except Exception as exc:
                await _fail(ws, "".join(traceback.format_exception(exc)))
                return
            finally:
                client.busy = False
                client.since = time.monotonic()
            await ws.send(payload)
            self.served += 1
            prev_total_ms = 1000 * (time.perf_counter() - start)

    async def _answer(self, client: _Client, request: dict[str, Any], gap: float) -> tuple[Action, float] | None:
        """Serve one decoded request of ``client``, ``gap`` s after its previous answer: a reset
        (None), or an observation (the action and the inference time in ms)."""
        assert client.policy is not None
        if request.get("endpoint") == RESET_ENDPOINT:
            client.acting = False
            await self._call(client.policy.reset, episode_context(request))
            client.needs_reset = False
            return None
        check_observation(request)
        if client.acting:
            client.cycle = gap if client.cycle is None else 0.7 * client.cycle + 0.3 * gap
        client.acting = True
        if client.needs_reset:
            await self._call(client.policy.reset, episode_context(request))
            client.needs_reset = False
        return await self._act(client, request)

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

    def _encode(self, action: Any, infer_ms: float, prev_total_ms: float | None) -> bytes:
        """The reply, refused (before encoding) when it would exceed the message limit."""
        if action_nbytes(action) > self.max_message_bytes:
            raise RequestError(f"the policy's reply ({action_nbytes(action)} bytes) exceeds the limit of "
                               f"{self.max_message_bytes} bytes")
        response = {str(k): (np.asarray(v) if isinstance(v, (list, tuple)) else v) for k, v in action.items()}
        response["server_timing"] = {"infer_ms": infer_ms}
        if prev_total_ms is not None:
            response["server_timing"]["prev_total_ms"] = prev_total_ms
        payload = packb(response)
        if len(payload) > self.max_message_bytes:
            raise RequestError(f"the policy's reply ({len(payload)} bytes) exceeds the limit of "
                               f"{self.max_message_bytes} bytes")
        return payload

    # inference ---------------------------------------------------------------------------
    async def _act(self, client: _Client, obs: dict[str, Any]) -> tuple[Action, float]:
        policy = client.policy
        assert policy is not None
        if not self.batching:
            assert self._infer_slots is not None
            async with self._infer_slots:
                t0 = time.perf_counter()
                action = await self._call(policy.act, obs)
                return action, 1000 * (time.perf_counter() - t0)
        assert self._wake is not None
        pending = _Pending(policy, obs, asyncio.get_running_loop().create_future())
        self._pending.append(pending)
        self._wake.set()
        client.queued = True
        try:
            return await pending.future
        finally:
            client.queued = False

    async def _batcher(self) -> None:
        """Collect pending requests into batches; one ``act_batch`` call at a time."""
        assert self._wake is not None
        try:
            while True:
                await self._wake.wait()
                self._wake.clear()
                if not self._pending:
                    continue
                deadline = self._pending[0].t + self.batch_timeout_s
                while len(self._pending) < min(self.max_batch, len(self._pending) + self._expected_clients()):
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        break
                    try:
                        await asyncio.wait_for(self._wake.wait(), remaining)
                    except TimeoutError:
                        break
                    self._wake.clear()
                batch, self._pending = self._pending[: self.max_batch], self._pending[self.max_batch:]
                results, infer_ms = await self._call(self._run_batch, batch)
                for item, result in zip(batch, results, strict=True):
                    if item.future.done():
                        continue
                    if isinstance(result, Exception):
                        item.future.set_exception(result)
                    else:
                        item.future.set_result((result, infer_ms))
                if self._pending:
                    self._wake.set()
        except asyncio.CancelledError:
            for item in self._pending:
                if not item.future.done():
                    item.future.set_exception(RuntimeError("server shutting down"))
            raise

    def _expected_clients(self) -> int:
        """Idle clients whose next request is due within their usual cycle (not those building a scene)."""
        now = time.monotonic()
        return sum(c.expected(now, self.batch_timeout_s) for c in self._clients)

    def _run_batch(self, batch: list[_Pending]) -> tuple[list[Any], float]:
        policies, observations = [b.policy for b in batch], [b.obs for b in batch]
        t0 = time.perf_counter()
        try:
            results = type(policies[0]).act_batch(policies, observations)
            if not isinstance(results, list) or len(results) != len(batch):
                raise TypeError(f"act_batch returned {type(results).__name__} for {len(batch)} observations")
        except Exception:  # cannot tell whose item broke the call: run each alone
            log.warning("batched act of %d failed; retrying each request alone", len(batch), exc_info=True)
            results = []
            for p, o in zip(policies, observations, strict=True):
                try:
                    results.append(type(p).act_batch([p], [o])[0])
                except Exception as exc:
                    results.append(exc)
        self.batch_sizes[len(batch)] += 1
        return results, 1000 * (time.perf_counter() - t0)


async def _fail(ws: ServerConnection, message: str) -> None:
    """openpi's error convention: the reason as a text frame, then close 1011."""
    log.warning("closing client %s: %s", ws.remote_address, message.strip().splitlines()[-1])
    with contextlib.suppress(ConnectionClosed):
        await ws.send(message)
        await ws.close(CloseCode.INTERNAL_ERROR, "request failed; reason in the previous frame")


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


#: ``policy.serve*`` switches of a run (see serving/run_server.py), not the policy's own options
RUN_SERVING_KEYS = frozenset({"serve", "serve_max_batch", "serve_batch_timeout_ms", "serve_transport"})


def build_server(plugins: Plugins, policy_cfg: dict[str, Any], server_cls: type[PolicyServer] = PolicyServer,
                 **options: Any) -> PolicyServer:
    """The server (a ``server_cls``: the websocket one, or a subclass's transport) for the policy
    plugin ``policy_cfg`` names in ``plugins`` (built when the server starts)."""
    from molmo_lerobot import __version__
    from molmo_lerobot.policies.factory import make_policy

    cfg = {k: v for k, v in policy_cfg.items() if k not in RUN_SERVING_KEYS}
    metadata = {"server": "molmo-serve", "version": __version__, "policy": cfg.get("name")}
    return server_cls(lambda: make_policy(plugins, cfg), metadata=metadata, **options)
