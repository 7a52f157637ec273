"""Synchronous client for openpi-compatible policy servers.

Speaks the openpi protocol (metadata frame on connect, then strict request -> response) and
adds what openpi's own client lacks: a timeout on every receive, reconnect with backoff, an
optional ``{"endpoint": "reset"}`` message, no keepalive pings by default (blocking inference
cannot stall them) and a maximum message size.
"""

from __future__ import annotations

import socket
import time
from typing import Any

from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus, InvalidURI
from websockets.sync.client import ClientConnection, connect

from molmo_lerobot.errors import InfrastructureError, MolmoError
from molmo_lerobot.protocol.codec import CodecError, packb, unpackb

RESET_ENDPOINT = "reset"


class PolicyClientError(MolmoError, RuntimeError):
    """Talking to the policy server failed; the message says where and why."""


class PolicyConnectionError(PolicyClientError, InfrastructureError):
    """The server could not be reached or dropped the connection: not the episode's failure."""


class PolicyTimeoutError(PolicyConnectionError, TimeoutError):
    """The server did not answer (or could not be reached) in time."""


class PolicyServerError(PolicyClientError):
    """The server reported an error (a text frame, openpi's convention); carries its message."""


class PolicyClient:
    """One websocket session with a policy server; reconnects lazily after a drop.

    ``infer(obs)`` sends one observation dict and returns the decoded response dict.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int | None = 8000,
        *,
        timeout_s: float = 60.0,
        connect_timeout_s: float = 30.0,
        max_message_bytes: int | None = 64 * 2**20,
        ping_interval_s: float | None = None,
        backoff_s: float = 0.2,
        api_key: str | None = None,
    ) -> None:
        if host.startswith(("ws://", "wss://")):
            self.uri = host if port is None else f"{host}:{port}"
        else:
            self.uri = f"ws://{host}" if port is None else f"ws://{host}:{port}"
        self.timeout_s = timeout_s
        self.connect_timeout_s = connect_timeout_s
        self.max_message_bytes = max_message_bytes
        self.ping_interval_s = ping_interval_s
        self.backoff_s = backoff_s
        self._headers = {"Authorization": f"Api-Key {api_key}"} if api_key else None
        self._conn: ClientConnection | None = None
        self.metadata: dict[str, Any] | None = None
        self.connects = 0

    # connection ---------------------------------------------------------------------------
    def connect(self) -> dict[str, Any]:
        """Connect (retrying with exponential backoff until ``connect_timeout_s``); return the metadata.
        A host name that does not resolve fails at once (:class:`PolicyClientError`); a refused or
        unanswered connection (a server still starting) is retried."""
        self.close()
        deadline = time.monotonic() + self.connect_timeout_s
        delay, attempts = self.backoff_s, 0
        last: BaseException | None = None
        while True:
            attempts += 1
            remaining = deadline - time.monotonic()
            try:
                conn = connect(
                    self.uri,
                    open_timeout=max(min(remaining, self.timeout_s), 0.1),
                    compression=None,
                    max_size=self.max_message_bytes,
                    ping_interval=self.ping_interval_s,
                    ping_timeout=None if self.ping_interval_s is None else max(self.timeout_s, 60.0),
                    close_timeout=2.0,
                    proxy=None,
                    additional_headers=self._headers,
                )
                break
            except InvalidURI as exc:
                raise PolicyClientError(f"bad policy server address {self.uri!r}: {exc}") from exc
            except socket.gaierror as exc:  # a name that does not resolve will not on a retry (unless DNS is down)
                if exc.errno == socket.EAI_AGAIN:
                    last = exc
                else:
                    raise PolicyClientError(f"policy server {self.uri}: its host name does not resolve "
                                            f"({exc.strerror or exc}); check policy.host") from None
            except (OSError, TimeoutError, InvalidHandshake) as exc:
                last = exc
            if time.monotonic() + delay > deadline:
                raise PolicyTimeoutError(
                    f"could not connect to policy server {self.uri} within {self.connect_timeout_s:g} s "
                    f"({attempts} attempts; last error: {_why(last)})"
                )
            time.sleep(delay)
            delay = min(delay * 2, 5.0)
        self._conn = conn
        try:
            metadata = self._receive("metadata frame")
        except _Stale:
            self.close()
            raise PolicyConnectionError(
                f"policy server {self.uri} closed the connection before its metadata frame") from None
        except PolicyClientError:
            self.close()
            raise
        if not isinstance(metadata, dict):
            self.close()
            raise PolicyClientError(f"policy server {self.uri} sent a {type(metadata).__name__} metadata frame, "
                                    "expected a dict")
        self.metadata = metadata
        self.connects += 1
        return metadata

    @property
    def connected(self) -> bool:
        return self._conn is not None

    def close(self) -> None:
        if self._conn is not None:
            try:
                self._conn.close()
            finally:
                self._conn = None

    def __enter__(self) -> PolicyClient:
        if self._conn is None:
            self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # requests -----------------------------------------------------------------------------
    def infer(self, obs: dict[str, Any]) -> dict[str, Any]:
        """Send one observation, return the server's response dict."""
        response = self._request(obs, "inference response")
        if not isinstance(response, dict):
            raise PolicyClientError(f"policy server {self.uri} answered with a {type(response).__name__}, "
                                    "expected a dict")
        return response

    def reset(self, **info: Any) -> dict[str, Any]:
        """Send ``{"endpoint": "reset", **info}`` (not part of openpi; for servers that support it)."""
        response = self._request({"endpoint": RESET_ENDPOINT, **info}, "reset acknowledgement")
        return response if isinstance(response, dict) else {"response": response}

    def _request(self, message: dict[str, Any], what: str) -> Any:
        payload = packb(message)
        # A connection may have gone stale between requests (server restart): one fresh retry,
        # but only when nothing was answered (never after a timeout or a server error).
        for attempt in (0, 1):
            if self._conn is None:
                self.connect()
            assert self._conn is not None  # connect() made it
            try:
                try:
                    self._conn.send(payload)
                except ConnectionClosed as exc:
                    raise _Stale() from exc
                return self._receive(what)
            except _Stale:
                self.close()
                if attempt:
                    raise PolicyConnectionError(
                        f"policy server {self.uri} closed the connection before answering") from None
        raise AssertionError("unreachable")

    def _receive(self, what: str) -> Any:
        assert self._conn is not None
        try:
            frame = self._conn.recv(timeout=self.timeout_s)
        except TimeoutError:
            self.close()
            raise PolicyTimeoutError(
                f"policy server {self.uri} sent no {what} within {self.timeout_s:g} s (connection dropped)"
            ) from None
        except ConnectionClosed as exc:
            code = exc.rcvd.code if exc.rcvd else None
            if code in (None, 1000, 1001, 1006):
                raise _Stale() from exc
            self.close()
            reason = " ".join((exc.rcvd.reason if exc.rcvd else "").split())
            error = PolicyClientError if code in _REFUSED else PolicyConnectionError
            raise error(f"policy server {self.uri} closed the connection (code {code}: {reason})") from None
        if isinstance(frame, str):
            self.close()
            last = frame.strip().splitlines()[-1] if frame.strip() else "(empty message)"
            raise PolicyServerError(f"policy server {self.uri} failed: {last}\n{frame}")
        try:
            return unpackb(frame)
        except CodecError as exc:
            self.close()
            raise PolicyClientError(f"policy server {self.uri} sent a malformed {what}: {exc}") from exc


class _Stale(MolmoError):
    """The connection closed without an answer (internal: triggers one reconnect)."""


#: close codes by which the server refuses the request itself (unsupported, invalid, policy,
#: too big): the same request would be refused again, so it is the episode's error
_REFUSED = {1003, 1007, 1008, 1009}


def _why(exc: BaseException | None) -> str:
    """A failed connection attempt in a few words of ours (no library text spanning lines)."""
    if isinstance(exc, InvalidStatus):
        return f"HTTP {exc.response.status_code} instead of a websocket handshake"
    if isinstance(exc, InvalidHandshake):
        return f"no valid websocket handshake ({type(exc).__name__})"
    if isinstance(exc, TimeoutError):
        return "no handshake in time"
    if isinstance(exc, OSError) and exc.strerror:
        return f"{type(exc).__name__}: {exc.strerror}"
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
