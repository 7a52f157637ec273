"""PolicyServer: metadata first, per-client state, errors confined to one client, healthz, shutdown."""

from __future__ import annotations

import http.client
import threading
from typing import ClassVar

import msgpack
import numpy as np
import pytest
from websockets.sync.client import connect

from molmo_lerobot.policies.base import Policy
from molmo_lerobot.protocol.client import PolicyClient, PolicyClientError, PolicyServerError
from molmo_lerobot.protocol.codec import packb, unpackb
from molmo_lerobot.serving.server import PolicyServer, serve_in_thread


class CountingPolicy(Policy):
    """Returns its own call count: shows per-connection state and resets."""

    instances: ClassVar[list[CountingPolicy]] = []

    def __init__(self) -> None:
        self.calls, self.prompt, self.closed = 0, None, False
        CountingPolicy.instances.append(self)

    def reset(self, ctx) -> None:
        self.calls, self.prompt = 0, ctx.prompt

    def act(self, obs):
        if obs.get("boom"):
            raise RuntimeError("policy exploded on purpose")
        self.calls += 1
        return {"arm": np.full((2, 7), self.calls, np.float32), "gripper": np.zeros((2, 1), np.float32)}

    def close(self) -> None:
        self.closed = True


# numpy 2 StringDType bytes hold pointers: printing such an array from wire bytes crashed molmo-serve
STRING_ARRAY_FRAME = msgpack.packb(
    {"tokens": {b"__ndarray__": True, b"data": b"\x41" * 16, b"dtype": "T", b"shape": [1]}}, use_bin_type=True
)
OBS = {"qpos": {"arm": np.zeros(7), "gripper": np.zeros(1)}, "prompt": "pick"}


@pytest.fixture
def server():
    CountingPolicy.instances.clear()
    srv = PolicyServer(CountingPolicy, port=0, metadata={"policy": "counting"}, max_clients=3, max_message_bytes=4096,
                      evict_idle_s=60)
    with serve_in_thread(srv) as running:
        yield running


def client(server, **kw) -> PolicyClient:
    return PolicyClient("127.0.0.1", server.port, timeout_s=5, connect_timeout_s=5, **kw)


def test_metadata_first_then_actions_per_client_state(server):
    a, b = client(server), client(server)
    assert a.connect() == {"policy": "counting", "needs_images": True, "needs_environment_state": False,
                           "batched": False}
    b.connect()
    for _ in range(3):
        out = a.infer(OBS)
    assert out["arm"].shape == (2, 7) and out["arm"][0, 0] == 3 and "infer_ms" in out["server_timing"]
    assert b.infer(OBS)["arm"][0, 0] == 1  # b has its own policy instance
    assert a.reset(prompt="place") == {"endpoint": "reset", "ok": True}
    assert a.infer(OBS)["arm"][0, 0] == 1
    assert "place" in [p.prompt for p in CountingPolicy.instances]
    a.close(), b.close()


def test_openpi_style_raw_client(server):
    with connect(f"ws://127.0.0.1:{server.port}", compression=None, max_size=None) as ws:
        assert unpackb(ws.recv(timeout=5))["policy"] == "counting"
        ws.send(packb(OBS))
        assert unpackb(ws.recv(timeout=5))["gripper"].shape == (2, 1)


@pytest.mark.parametrize(
    "frame, reason",
    [
        (b"\xc1 not msgpack", "malformed msgpack"),
        ("a text frame", "expected a binary msgpack frame"),
        (packb([1, 2, 3]), "must be a msgpack map"),
        (packb({"x": np.zeros(1000)}), "exceeds the limit of 4096 bytes"),
        (packb({"boom": True}), "policy exploded on purpose"),
        (STRING_ARRAY_FRAME, "refusing dtype 'T'"),
    ],
)
def test_bad_request_closes_only_that_client(server, frame, reason):
    good = client(server)
    good.infer(OBS)
    with connect(f"ws://127.0.0.1:{server.port}", compression=None) as ws:
        ws.recv(timeout=5)
        ws.send(frame)
        error = ws.recv(timeout=5)
        assert isinstance(error, str) and reason in error
        with pytest.raises(Exception) as closed:
            ws.recv(timeout=5)
        assert closed.value.rcvd.code == 1011
    assert good.infer(OBS)["arm"][0, 0] == 2  # the other client is unaffected
    assert client(server).infer(OBS)["arm"][0, 0] == 1  # and new ones are served


def test_server_error_reaches_client_as_exception(server):
    c = client(server)
    with pytest.raises(PolicyServerError, match="RuntimeError: policy exploded on purpose"):
        c.infer({"boom": True})
    assert not c.connected
    assert c.infer(OBS)["arm"][0, 0] == 1  # reconnects on the next call


def test_healthz_and_client_limit(server):
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=5)
    conn.request("GET", "/healthz")
    assert conn.getresponse().status == 200
    clients = [client(server) for _ in range(3)]
    for c in clients:
        c.connect()
    extra = PolicyClient("127.0.0.1", server.port, timeout_s=2, connect_timeout_s=0.5)
    with pytest.raises(PolicyClientError, match=r"could not connect.*503"):
        extra.connect()
    clients[0].close()
    for c in clients[1:]:
        assert c.infer(OBS)["arm"][0, 0] == 1


def test_graceful_shutdown_closes_policies():
    CountingPolicy.instances.clear()
    srv = PolicyServer(CountingPolicy, port=0)
    with serve_in_thread(srv):
        c = PolicyClient("127.0.0.1", srv.port, timeout_s=5)
        c.infer(OBS)
    assert CountingPolicy.instances and all(p.closed for p in CountingPolicy.instances)
    assert not any(t.name == "policy-server" for t in threading.enumerate())
