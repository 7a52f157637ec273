"""A same-machine policy transport without serialisation: arrays in shared memory, indices on a socket.

Each side writes its arrays into a **segment** it owns: an anonymous ``memfd`` (Linux), sealed
against shrinking and growing, whose file descriptor travels once over the control socket
(``SCM_RIGHTS``) and which the other side maps read-only. Segments have no name, so nothing is
ever left in ``/dev/shm``: the kernel frees one when the last process holding it exits, however
it exits (``kill -9`` included). A worker's segment is a ring of :data:`RING` frames, written in
turn, so the arrays a server's policy was handed stay valid until the request after next; the
server's action segment is copied out by the client (actions are small).

The control channel is an ``AF_UNIX`` ``SOCK_SEQPACKET`` socket in the abstract namespace
(``@molmo-serve-…``: no file either), one connection per client, strictly request → response.
Abstract names carry no permissions, so each side checks the other's user (``SO_PEERCRED``)
before it sends anything: a server accepts only its own user's clients, a client only its own
user's server.
Its messages are small msgpack maps (:mod:`molmo_lerobot.protocol.codec`) in which every array
is replaced by a descriptor ``{"__shm__": [offset, dtype, shape]}`` into the sender's current
frame; prompts, step indices and numpy scalars travel in the map itself. On connect the server
sends the metadata map; then the client sends resets (``{"endpoint": "reset", …}``, the
websocket protocol's) and observations ``{"obs": tree, "frame": k}``, and the server answers
``{"action": tree, "server_timing": …}`` or ``{"error": text, "kind": "request" | "policy"}``
before closing the connection. Descriptors are checked against the mapped frame (in bounds,
dtype in :data:`~molmo_lerobot.protocol.codec.ALLOWED_DTYPES`, at most :data:`MAX_NDIM` axes).
"""

from __future__ import annotations

import contextlib
import fcntl
import math
import mmap
import os
import secrets
import socket
import struct
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from molmo_lerobot.errors import InfrastructureError
from molmo_lerobot.protocol.client import (
    RESET_ENDPOINT,
    PolicyClientError,
    PolicyConnectionError,
    PolicyServerError,
    PolicyTimeoutError,
)
from molmo_lerobot.protocol.codec import CodecError, allowed_dtype, packb, unpackb

RING = 2  #: frames in a client's observation segment
ALIGN = 64  #: every array starts on a cache line
MAX_NDIM = 8
MAX_HEADER_BYTES = 1 << 16  #: a control message (the map, without the arrays; a prompt is at most 8192 characters)
_DESC = "__shm__"
_SEALS = fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL if hasattr(fcntl, "F_SEAL_SHRINK") else 0


class ShmTransportError(PolicyClientError, InfrastructureError):
    """The shared-memory transport itself failed (a refused descriptor or segment, a busy server):
    the machinery's failure, not the episode's."""


def available() -> bool:
    """Whether this machine has what the transport needs (Linux: memfd with seals, abstract sockets)."""
    return sys.platform.startswith("linux") and hasattr(os, "memfd_create") and bool(_SEALS)


def new_address() -> str:
    """A fresh abstract socket address (``@`` stands for the leading NUL byte)."""
    return f"@molmo-serve-{os.getpid()}-{secrets.token_hex(6)}"


def sock_address(address: str) -> str:
    return "\0" + address[1:] if address.startswith("@") else address


def peer_credentials(sock: socket.socket) -> tuple[int, int]:
    """``(pid, uid)`` of the process at the other end of a connected ``AF_UNIX`` socket (``SO_PEERCRED``)."""
    pid, uid, _gid = struct.unpack("3i", sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, 12))
    return pid, uid


class Segment:
    """A writer's sealed memfd of ``frames`` equal frames, replaced by a bigger one when a tree outgrows it."""

    def __init__(self, name: str, frames: int = 1) -> None:
        self.name, self.frames = name, frames
        self.fd: int | None = None
        self.map: mmap.mmap | None = None
        self.frame_bytes = 0
        self.generation = 0  # bumped on every new memfd (the peer must be sent the new one)

    def write(self, tree: Any, frame: int = 0) -> Any:
        """``tree`` with each array copied into ``frame`` and replaced by its descriptor."""
        arrays: list[np.ndarray] = []
        skeleton = _strip(tree, arrays)
        offsets, total = [], 0
        for arr in arrays:
            offsets.append(total)
            total += -(-arr.nbytes // ALIGN) * ALIGN
        if total > self.frame_bytes:
            self._grow(-(-max(total + total // 4, 4096) // ALIGN) * ALIGN)  # frames start aligned too
        assert self.map is not None
        base = frame * self.frame_bytes
        for arr, off in zip(arrays, offsets, strict=True):
            np.copyto(np.ndarray(arr.shape, arr.dtype, buffer=self.map, offset=base + off), arr, casting="no")
        descriptors = iter([off, arr.dtype.str, list(arr.shape)] for arr, off in zip(arrays, offsets, strict=True))
        return _fill(skeleton, descriptors)

    def _grow(self, frame_bytes: int) -> None:
        self.close()
        fd = os.memfd_create(self.name, os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
        try:
            os.ftruncate(fd, frame_bytes * self.frames)
            fcntl.fcntl(fd, fcntl.F_ADD_SEALS, _SEALS)
            self.map = mmap.mmap(fd, frame_bytes * self.frames)
        except BaseException:
            os.close(fd)
            raise
        self.fd, self.frame_bytes = fd, frame_bytes
        self.generation += 1

    def close(self) -> None:
        if self.map is not None:
            self.map.close()
            self.map = None
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
        self.frame_bytes = 0


class Mapping:
    """A reader's read-only map of the peer's segment, received as ``fd`` (closed here)."""

    def __init__(self, fd: int, frames: int, max_bytes: int) -> None:
        try:
            size = os.fstat(fd).st_size
            seals = fcntl.fcntl(fd, fcntl.F_GET_SEALS)
            if seals & fcntl.F_SEAL_SHRINK == 0:
                raise ShmTransportError("shared memory segment is not sealed against shrinking")
            if not 0 < size <= max_bytes * frames or size % frames:
                raise ShmTransportError(f"shared memory segment of {size} bytes for {frames} frames "
                                        f"(at most {max_bytes} bytes a frame)")
            self.map = mmap.mmap(fd, size, access=mmap.ACCESS_READ)
        except OSError as exc:
            raise ShmTransportError(f"not a shared memory segment: {exc.strerror or exc}") from None
        finally:
            os.close(fd)
        self.frames, self.frame_bytes = frames, size // frames

    def read(self, tree: Any, frame: Any) -> Any:
        """``tree`` with each descriptor replaced by a read-only view into ``frame``."""
        if isinstance(frame, bool) or not isinstance(frame, int) or not 0 <= frame < self.frames:
            raise ShmTransportError(f"frame must be an integer in [0, {self.frames}), got {frame!r:.40}")
        return _views(tree, self.map, frame * self.frame_bytes, self.frame_bytes)

    def close(self) -> None:
        with contextlib.suppress(BufferError):  # views still alive: the map goes with the last of them
            self.map.close()


def _strip(tree: Any, arrays: list[np.ndarray]) -> Any:
    if isinstance(tree, np.ndarray):
        allowed_dtype(tree.dtype)
        arrays.append(tree)
        return {_DESC: None}
    if isinstance(tree, dict):
        return {k: _strip(v, arrays) for k, v in tree.items()}
    if isinstance(tree, (list, tuple)):
        return [_strip(v, arrays) for v in tree]
    return tree


def _fill(tree: Any, descriptors: Any) -> Any:
    if isinstance(tree, dict):
        return {_DESC: next(descriptors)} if _DESC in tree else {k: _fill(v, descriptors) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_fill(v, descriptors) for v in tree]
    return tree


def _views(tree: Any, buf: mmap.mmap, base: int, size: int) -> Any:
    if isinstance(tree, dict):
        if _DESC not in tree:
            return {k: _views(v, buf, base, size) for k, v in tree.items()}
        desc = tree[_DESC]
        if len(tree) != 1 or not isinstance(desc, list) or len(desc) != 3:
            raise ShmTransportError(f"malformed array descriptor {desc!r:.60}")
        offset, dtype_name, shape = desc
        try:
            dtype = allowed_dtype(dtype_name)
        except CodecError as exc:
            raise ShmTransportError(str(exc)) from None
        if (not isinstance(shape, list) or len(shape) > MAX_NDIM
                or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in shape)):
            raise ShmTransportError(f"array shape must be at most {MAX_NDIM} non-negative ints, got {shape!r:.60}")
        if any(s > size for s in shape):  # no side of an array in the frame is longer than the frame
            raise ShmTransportError(f"array shape {shape!r:.60} does not fit the {size}-byte frame")
        nbytes = math.prod(shape) * dtype.itemsize  # Python ints: a huge shape cannot wrap to a small size
        if isinstance(offset, bool) or not isinstance(offset, int) or offset < 0 or offset + nbytes > size:
            raise ShmTransportError(f"array of {nbytes} bytes at offset {offset!r:.20} is outside the "
                                    f"{size}-byte frame")
        return np.ndarray(tuple(shape), dtype, buffer=buf, offset=base + offset)  # read-only map: read-only view
    if isinstance(tree, list):
        return [_views(v, buf, base, size) for v in tree]
    return tree


def send(sock: socket.socket, message: dict[str, Any], fd: int | None = None) -> None:
    """One control message (and a segment's fd)."""
    payload = packb(message)
    if len(payload) > MAX_HEADER_BYTES:
        raise CodecError(f"control message of {len(payload)} bytes exceeds {MAX_HEADER_BYTES}")
    if fd is None:
        sock.sendall(payload)
    else:
        socket.send_fds(sock, [payload], [fd])


def parse(data: bytes, fds: list[int], flags: int) -> tuple[dict[str, Any], int | None]:
    """A received control message and the fd it carried; closes extra fds, refuses the malformed."""
    for extra in fds[1:]:
        os.close(extra)
    fd = fds[0] if fds else None
    try:
        if flags & (socket.MSG_TRUNC | socket.MSG_CTRUNC):
            raise ShmTransportError(f"control message longer than {MAX_HEADER_BYTES} bytes or with several fds")
        try:
            message = unpackb(data)
        except CodecError as exc:
            raise ShmTransportError(f"malformed control message: {exc}") from None
        if not isinstance(message, dict):
            raise ShmTransportError(f"control message must be a map, got {type(message).__name__}")
    except BaseException:
        if fd is not None:
            os.close(fd)
        raise
    return message, fd


class ShmPolicyClient:
    """The :class:`~molmo_lerobot.protocol.client.PolicyClient` interface over shared memory:
    ``connect()`` → metadata, ``reset(**info)``, ``infer(obs)``, ``connects``, lazy reconnects."""

    def __init__(self, address: str, *, timeout_s: float = 60.0, connect_timeout_s: float = 30.0,
                 max_message_bytes: int = 64 * 2**20, backoff_s: float = 0.2) -> None:
        self.uri = f"shm+unix:{address}"
        self.address = address
        self.timeout_s, self.connect_timeout_s, self.backoff_s = timeout_s, connect_timeout_s, backoff_s
        self.max_message_bytes = max_message_bytes
        self._sock: socket.socket | None = None
        self._obs = Segment("molmo-obs", RING)
        self._sent_generation = 0
        self._actions: Mapping | None = None
        self._frame = 0
        self.metadata: dict[str, Any] | None = None
        self.connects = 0

    def connect(self) -> dict[str, Any]:
        """Connect (retrying with backoff until ``connect_timeout_s``); return the server's metadata.

        A server of another user (``SO_PEERCRED``) is refused before anything is sent or read:
        abstract socket names are visible to every local user, who could bind a dead server's name.
        """
        self.close()
        deadline = time.monotonic() + self.connect_timeout_s
        delay, attempts = self.backoff_s, 0
        while True:
            attempts += 1
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            sock.settimeout(self.timeout_s)
            try:
                sock.connect(sock_address(self.address))
                break
            except OSError as exc:
                sock.close()
                if time.monotonic() + delay > deadline:
                    raise PolicyTimeoutError(f"could not connect to policy server {self.uri} within "
                                             f"{self.connect_timeout_s:g} s ({attempts} attempts; last error: "
                                             f"{type(exc).__name__}: {exc.strerror or exc})") from None
            time.sleep(delay)
            delay = min(delay * 2, 5.0)
        pid, uid = peer_credentials(sock)
        if uid != os.getuid():
            sock.close()
            raise ShmTransportError(f"policy server {self.uri} (process {pid}) runs as user {uid}, not as this "
                                    f"process's user {os.getuid()}: refused, nothing sent")
        self._sock, self._sent_generation, self._frame = sock, 0, 0
        metadata = self._receive("metadata message", None)
        self.metadata = metadata
        self.connects += 1
        return metadata

    @property
    def connected(self) -> bool:
        return self._sock is not None

    def close(self) -> None:
        """Close the connection and both segments' maps (a later request reconnects with new ones)."""
        if self._actions is not None:
            self._actions.close()
            self._actions = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        self._obs.close()

    def __enter__(self) -> ShmPolicyClient:
        if self._sock is None:
            self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def reset(self, **info: Any) -> dict[str, Any]:
        """``{"endpoint": "reset", **info}``: the server resets this connection's policy."""
        return self._request(lambda: ({"endpoint": RESET_ENDPOINT, **info}, None), "reset acknowledgement")

    def infer(self, obs: dict[str, Any]) -> dict[str, Any]:
        """Write ``obs``'s arrays into the next frame, send their descriptors; return the action dict
        (with ``server_timing``, as the websocket client does)."""

        def message() -> tuple[dict[str, Any], int | None]:
            self._frame = (self._frame + 1) % RING
            tree = self._obs.write(obs, self._frame)
            fd = self._obs.fd if self._sent_generation != self._obs.generation else None
            self._sent_generation = self._obs.generation
            return {"obs": tree, "frame": self._frame}, fd

        response = self._request(message, "inference response")
        action = response.get("action")
        if not isinstance(action, dict):
            self.close()
            raise ShmTransportError(f"policy server {self.uri} sent no action map")
        return {**action, "server_timing": response.get("server_timing")}

    def _request(self, build: Callable[[], tuple[dict[str, Any], int | None]], what: str) -> dict[str, Any]:
        # A connection may have gone stale between requests (server restart): one fresh retry,
        # but only when nothing was answered (never after a timeout or a server error).
        for attempt in (0, 1):
            if self._sock is None:
                self.connect()
            assert self._sock is not None
            message, fd = build()
            try:
                send(self._sock, message, fd)
            except (BrokenPipeError, ConnectionResetError):
                self.close()
                if attempt:
                    raise PolicyConnectionError(
                        f"policy server {self.uri} closed the connection before answering") from None
                continue
            except OSError as exc:
                self.close()
                raise PolicyConnectionError(f"policy server {self.uri}: send failed: {exc.strerror or exc}") from None
            return self._receive(what, message)
        raise AssertionError("unreachable")

    def _receive(self, what: str, request: dict[str, Any] | None) -> dict[str, Any]:
        assert self._sock is not None
        try:
            data, fds, flags, _ = socket.recv_fds(self._sock, MAX_HEADER_BYTES, 1)
        except TimeoutError:
            self.close()
            raise PolicyTimeoutError(f"policy server {self.uri} sent no {what} within {self.timeout_s:g} s "
                                     "(connection dropped)") from None
        except OSError as exc:
            self.close()
            raise PolicyConnectionError(f"policy server {self.uri} dropped the connection: "
                                        f"{exc.strerror or exc}") from None
        if not data and not fds:
            self.close()
            raise PolicyConnectionError(f"policy server {self.uri} closed the connection before its {what}")
        try:
            message, fd = parse(data, fds, flags)
            if fd is not None:
                if self._actions is not None:
                    self._actions.close()
                self._actions = Mapping(fd, 1, self.max_message_bytes)
            if "error" in message:
                text = str(message["error"])
                line = text.strip().splitlines()[-1] if text.strip() else "(empty message)"
                error = PolicyServerError if message.get("kind") == "policy" else ShmTransportError
                raise error(f"policy server {self.uri} failed: {line}" + ("\n" + text) * (error is PolicyServerError))
            if "action" in message:
                if self._actions is None:
                    raise ShmTransportError(f"policy server {self.uri} answered before sending its action segment")
                message["action"] = _copy(self._actions.read(message["action"], 0))
        except PolicyClientError:
            self.close()
            raise
        return message


def _copy(tree: Any) -> Any:
    """Actions leave the server's segment (the rollout keeps chunks for many steps)."""
    if isinstance(tree, np.ndarray):
        return tree.copy()
    if isinstance(tree, dict):
        return {k: _copy(v) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_copy(v) for v in tree]
    return tree
