"""PolicyClient against openpi-like servers: timeouts, reconnects, server errors."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest
from droid_server import FakeDroidServer

from molmo_lerobot.protocol.client import PolicyClient, PolicyClientError, PolicyTimeoutError

OBS = {
    "observation/exterior_image_1_left": np.zeros((224, 224, 3), np.uint8),
    "observation/wrist_image_left": np.zeros((224, 224, 3), np.uint8),
    "observation/joint_position": np.zeros(7),
    "observation/gripper_position": np.zeros(1),
    "prompt": "pick the mug",
}


def test_talks_to_openpi_style_server():
    with FakeDroidServer(horizon=15).running() as srv:
        c = PolicyClient("127.0.0.1", srv.port, timeout_s=5)
        assert c.connect() == {"policy": "fake-droid"}
        assert c.infer(OBS)["actions"].shape == (15, 8)
        assert srv.errors == []


def test_string_dtype_from_a_hostile_server_is_refused():
    with FakeDroidServer(mode="string_dtype").running() as srv:
        c = PolicyClient("127.0.0.1", srv.port, timeout_s=5)
        with pytest.raises(PolicyClientError, match="malformed inference response: refusing dtype 'T'"):
            c.infer(OBS)
        assert not c.connected


def test_server_that_never_answers_times_out():
    with FakeDroidServer(mode="silent").running() as srv:
        c = PolicyClient("127.0.0.1", srv.port, timeout_s=0.5)
        t0 = time.monotonic()
        with pytest.raises(PolicyTimeoutError, match=r"sent no inference response within 0.5 s"):
            c.infer(OBS)
        assert time.monotonic() - t0 < 3 and not c.connected


def test_server_that_never_sends_metadata_times_out():
    with (FakeDroidServer(mode="silent_metadata").running() as srv,
          pytest.raises(PolicyTimeoutError, match=r"sent no metadata frame within 0.5 s")):
        PolicyClient("127.0.0.1", srv.port, timeout_s=0.5).connect()


def test_tcp_listener_that_never_handshakes_times_out():
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen(8)
        c = PolicyClient("127.0.0.1", sock.getsockname()[1], timeout_s=0.3, connect_timeout_s=1.0)
        with pytest.raises(PolicyTimeoutError, match=r"could not connect .* within 1 s"):
            c.connect()


def test_connect_retries_with_backoff_until_server_is_up():
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    c = PolicyClient("127.0.0.1", port, timeout_s=1, connect_timeout_s=0.6, backoff_s=0.05)
    t0 = time.monotonic()
    with pytest.raises(PolicyTimeoutError, match=r"\d+ attempts; last error: ConnectionRefusedError"):
        c.connect()
    assert 0.3 < time.monotonic() - t0 < 3


def test_reconnects_after_server_restart():
    srv = FakeDroidServer(horizon=4)
    with srv.running():
        c = PolicyClient("127.0.0.1", srv.port, timeout_s=5)
        c.infer(OBS)
    # A new server on the same port: the client's stale connection is replaced transparently.
    with FakeDroidServer(horizon=6, port=srv.port).running():
        assert c.infer(OBS)["actions"].shape == (6, 8)
        assert c.connects == 2


def _http_listener(reply: bytes):
    """A TCP server on a free port that answers every connection with ``reply`` and closes it."""
    import threading

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(8)

    def serve():
        while True:
            try:
                conn, _ = sock.accept()
            except OSError:
                return
            with conn:
                conn.recv(4096)
                conn.sendall(reply)

    threading.Thread(target=serve, daemon=True).start()
    return sock


@pytest.mark.parametrize(("reply", "why"), [
    (b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\n\r\n", "HTTP 503 instead of a websocket handshake"),
    (b"", "no valid websocket handshake (InvalidMessage)"),
])
def test_an_unreachable_server_is_one_line_naming_it_and_an_infrastructure_failure(reply, why):
    """A server that is gone or answers no handshake: one line of ours naming the URL, and an
    infrastructure failure (``resume=true`` reruns such an episode), never websockets' own text."""
    from molmo_lerobot.errors import describe, error_kind

    with _http_listener(reply) as sock:
        port = sock.getsockname()[1]
        c = PolicyClient("127.0.0.1", port, timeout_s=0.5, connect_timeout_s=0.3, backoff_s=0.05)
        with pytest.raises(PolicyTimeoutError) as info:
            c.connect()
    line = describe(info.value)
    assert f"ws://127.0.0.1:{port}" in line and "\n" not in line
    assert f"last error: {why})" in line, line
    assert error_kind(info.value) == "infrastructure"


def test_a_server_lost_mid_session_is_an_infrastructure_failure():
    from molmo_lerobot.errors import error_kind
    from molmo_lerobot.protocol.client import PolicyConnectionError

    srv = FakeDroidServer(horizon=4)
    with srv.running():
        c = PolicyClient("127.0.0.1", srv.port, timeout_s=1, connect_timeout_s=0.3, backoff_s=0.05)
        c.infer(OBS)
    with pytest.raises(PolicyConnectionError, match=f"policy server ws://127.0.0.1:{srv.port} ") as info:
        c.infer(OBS)  # the stale connection fails, the reconnect finds nobody
    assert error_kind(info.value) == "infrastructure"
