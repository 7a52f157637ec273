"""The policy server over shared memory (:mod:`molmo_lerobot.protocol.shm`): ``policy.serve=true``'s
transport when the workers run on the server's machine.

Everything but the transport is the websocket server's (:class:`~molmo_lerobot.serving.server.PolicyServer`):
a policy per connection, the same batcher (``max_batch``, ``batch_timeout_ms``, clients in step
wait for each other), the same checks of each observation, the same statistics. Observations
reach the policy as read-only numpy views into the worker's segment (no copy, no decoding); the
action is written into a segment of the server's per connection. Only clients of this user
(``SO_PEERCRED``; a client checks the server's user the same way) are accepted, at most
``max_clients`` at a time (a surplus client is told the server is busy). A refused request (a bad
descriptor, segment or observation) or a failing policy ends that connection only, with an error
message naming the reason.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import time
import traceback
from typing import Any

from molmo_lerobot.protocol.shm import (
    MAX_HEADER_BYTES,
    RING,
    Mapping,
    Segment,
    ShmTransportError,
    new_address,
    parse,
    peer_credentials,
    send,
    sock_address,
)
from molmo_lerobot.serving.native import RequestError, action_nbytes
from molmo_lerobot.serving.server import PolicyServer, _Client

log = logging.getLogger(__name__)


class ShmPolicyServer(PolicyServer):
    """A :class:`PolicyServer` whose clients connect at ``address`` (default: a fresh abstract one)."""

    transport = "shm"

    def __init__(self, *args: Any, address: str | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.address = address or new_address()
        self._listener: socket.socket | None = None
        self._sessions: set[asyncio.Task] = set()

    @property
    def endpoint(self) -> str:
        return f"shm+unix:{self.address}"

    async def _open(self) -> None:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        sock.bind(sock_address(self.address))
        sock.listen(self.max_clients)
        sock.setblocking(False)
        self._listener = sock
        asyncio.get_running_loop().add_reader(sock.fileno(), self._accept)

    def _accept(self) -> None:
        assert self._listener is not None
        try:
            conn, _ = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        conn.setblocking(False)
        task = asyncio.get_running_loop().create_task(self._handle_shm(conn))
        self._sessions.add(task)
        task.add_done_callback(self._sessions.discard)

    async def _shut(self) -> None:
        assert self._listener is not None
        asyncio.get_running_loop().remove_reader(self._listener.fileno())
        self._listener.close()
        for task in list(self._sessions):
            task.cancel()
        await asyncio.gather(*self._sessions, return_exceptions=True)

    async def _handle_shm(self, conn: socket.socket) -> None:
        client = _Client(conn)
        obs: Mapping | None = None
        actions = Segment("molmo-actions")
        self._clients.add(client)
        try:
            _, uid = peer_credentials(conn)
            if uid != os.getuid():
                await _send(conn, {"error": f"client of user {uid} refused", "kind": "request"})
                return
            if self.active > self.max_clients:
                await _send(conn, {"error": f"server busy ({self.max_clients} clients)", "kind": "request"})
                return
            try:
                client.policy = await self._call(self._new_policy)
            except Exception:
                await _send(conn, {"error": traceback.format_exc(), "kind": "policy"})
                return
            await _send(conn, self.metadata)
            client.since = time.monotonic()
            timeout = self.first_request_timeout_s
            prev_total_ms = None
            while True:
                try:
                    received = await asyncio.wait_for(_recv(conn), timeout)
                except TimeoutError:
                    log.info("closing shm client: no request for %g s", timeout)
                    return
                if received is None:
                    return  # the client went away (closed, or killed)
                timeout = self.idle_timeout_s
                client.busy = True
                start = time.perf_counter()
                gap = time.monotonic() - client.since
                try:
                    message, fd = parse(*received)
                    if fd is not None:
                        if obs is not None:
                            obs.close()
                        obs = Mapping(fd, RING, self.max_message_bytes)
                    if "obs" in message:
                        if obs is None:
                            raise ShmTransportError("observation before its shared memory segment")
                        request = obs.read(message["obs"], message.get("frame"))
                        if not isinstance(request, dict):
                            raise RequestError(f"observation must be a map, got {type(request).__name__}")
                    else:
                        request = message
                    answer = await self._answer(client, request, gap)
                    if answer is None:
                        reply, reply_fd = {"endpoint": "reset", "ok": True}, None
                    else:
                        reply, reply_fd = self._reply(actions, *answer, prev_total_ms)
                except (RequestError, ShmTransportError) as exc:
                    await _send(conn, {"error": f"{type(exc).__name__}: {exc}", "kind": "request"})
                    return
                except Exception as exc:
                    await _send(conn, {"error": "".join(traceback.format_exception(exc)), "kind": "policy"})
                    return
                finally:
                    client.busy = False
                    client.since = time.monotonic()
                if not await _send(conn, reply, reply_fd):
                    return
                if answer is not None:
                    self.served += 1
                prev_total_ms = 1000 * (time.perf_counter() - start)
        finally:
            self._clients.discard(client)
            if client.policy is not None:
                with contextlib.suppress(Exception):
                    await self._call(client.policy.close)
            if obs is not None:
                obs.close()
            actions.close()
            conn.close()

    def _reply(self, actions: Segment, action: Any, infer_ms: float,
               prev_total_ms: float | None) -> tuple[dict[str, Any], int | None]:
        """The action written into the connection's segment (a new one sent along when it grew)."""
        if action_nbytes(action) > self.max_message_bytes:
            raise RequestError(f"the policy's reply ({action_nbytes(action)} bytes) exceeds the limit of "
                               f"{self.max_message_bytes} bytes")
        generation = actions.generation
        tree = actions.write({str(k): v for k, v in action.items()}, 0)
        timing = {"infer_ms": infer_ms, **({"prev_total_ms": prev_total_ms} if prev_total_ms is not None else {})}
        return {"action": tree, "server_timing": timing}, actions.fd if actions.generation != generation else None


async def _recv(conn: socket.socket) -> tuple[bytes, list[int], int] | None:
    """The next message (bytes, fds, flags), or None once the peer is gone."""
    loop = asyncio.get_running_loop()
    while True:
        try:
            data, fds, flags, _ = socket.recv_fds(conn, MAX_HEADER_BYTES, 1)
        except (BlockingIOError, InterruptedError):
            await _until(loop.add_reader, loop.remove_reader, conn)
            continue
        except OSError:
            return None
        return None if not data and not fds else (data, fds, flags)


async def _until(watch: Any, unwatch: Any, conn: socket.socket) -> None:
    """Wait until the event loop reports ``conn`` ready (``watch``/``unwatch``: the loop's
    ``add_reader``/``remove_reader`` or ``add_writer``/``remove_writer``)."""
    ready = asyncio.get_running_loop().create_future()
    watch(conn.fileno(), ready.set_result, None)
    try:
        await ready
    finally:
        unwatch(conn.fileno())


async def _send(conn: socket.socket, message: dict[str, Any], fd: int | None = None) -> bool:
    """Send one message; False when the peer is gone."""
    loop = asyncio.get_running_loop()
    while True:
        try:
            send(conn, message, fd)
            return True
        except (BlockingIOError, InterruptedError):
            await _until(loop.add_writer, loop.remove_writer, conn)
        except OSError:
            return False
