"""Issue 11 item 6: everything a client can ask of the policy server is bounded, idle connections
time out quickly and never lock active clients out, and well-behaved clients keep being served."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from molmo_lerobot.policies.base import Policy
from molmo_lerobot.policies.random_policy import RandomPolicy
from molmo_lerobot.protocol.client import PolicyClient, PolicyServerError
from molmo_lerobot.protocol.codec import unpackb
from molmo_lerobot.serving.server import PolicyServer, serve_in_thread

OBS = {"qpos": {"arm": np.zeros(7), "gripper": np.zeros(1)}, "prompt": "pick"}


def random_server(**kw) -> PolicyServer:
    return PolicyServer(lambda: RandomPolicy({}), port=0, **kw)


def client(srv, **kw) -> PolicyClient:
    return PolicyClient("127.0.0.1", srv.port, timeout_s=5, connect_timeout_s=5, **kw)


def raw(srv):
    ws = connect(f"ws://127.0.0.1:{srv.port}", compression=None, open_timeout=5)
    unpackb(ws.recv(timeout=5))  # metadata
    return ws


def test_huge_move_groups_in_a_reset_are_refused():
    # issue: {"gripper": 20000000} plus a 185-byte observation made a 1.28 GB reply
    with serve_in_thread(random_server()) as srv:
        c = client(srv)
        with pytest.raises(PolicyServerError, match=r"move_groups\['gripper'\] must be an integer in \[1, 256\]"):
            c.reset(move_groups={"gripper": 20_000_000}, seed=1)
        with pytest.raises(PolicyServerError, match="move_groups has 17 groups"):
            c.reset(move_groups={f"g{i}": 1 for i in range(17)})
        c.reset(move_groups={"arm": 7, "gripper": 1}, seed=1)  # a sane reset still works
        assert c.infer(OBS)["arm"].shape == (8, 7)


@pytest.mark.parametrize("obs, match", [
    ({"qpos": {"arm": np.zeros((4000, 1)), "gripper": np.zeros(1)}}, r"qpos\['arm'\] must be a 1-d numeric array"),
    ({"qpos": {"arm": np.zeros(300), "gripper": np.zeros(1)}}, r"qpos\['arm'\] has shape \(300,\); at most 256"),
    ({**OBS, "images": {"cam": np.zeros((5000, 2, 3), np.uint8)}}, r"images\['cam'\] has shape \(5000, 2, 3\)"),
    ({**OBS, "prompt": "x" * 10_000}, "prompt must be a string of at most 8192"),
])
def test_observation_sizes_are_bounded(obs, match):
    with serve_in_thread(random_server()) as srv:
        with pytest.raises(PolicyServerError, match=match):
            client(srv).infer(obs)
        assert client(srv).infer(OBS)["gripper"].shape == (8, 1)


class HugeReplyPolicy(Policy):
    def reset(self, ctx) -> None:
        pass

    def act(self, obs):
        return {"arm": np.zeros((200_000, 7)), "gripper": np.zeros((200_000, 1))}


def test_reply_size_is_bounded_before_encoding():
    with (serve_in_thread(PolicyServer(HugeReplyPolicy, port=0, max_message_bytes=2**20)) as srv,
          pytest.raises(PolicyServerError, match=r"reply \(12800000 bytes\) exceeds the limit of 1048576 bytes")):
        client(srv).infer(OBS)


def test_connection_that_never_sends_is_closed_quickly():
    with serve_in_thread(random_server(first_request_timeout_s=0.5)) as srv:
        ws = raw(srv)
        t0 = time.monotonic()
        with pytest.raises(ConnectionClosed) as closed:
            ws.recv(timeout=5)
        assert closed.value.rcvd.code == 1001 and "no request for 0.5 s" in closed.value.rcvd.reason
        assert time.monotonic() - t0 < 3


def test_idle_connections_never_lock_out_an_active_client():
    # issue: 8 connections that never send blocked every other client with 503 for 600 s
    with serve_in_thread(random_server(max_clients=8, first_request_timeout_s=60, evict_idle_s=0.3)) as srv:
        hostile = [raw(srv) for _ in range(8)]
        time.sleep(0.4)
        t0 = time.monotonic()
        good = client(srv)
        good.reset(seed=3)
        assert good.infer(OBS)["arm"].shape == (8, 7)
        assert time.monotonic() - t0 < 3
        assert srv.active <= 8 and srv.evictions == 1
        for ws in hostile:
            ws.close()


def test_active_clients_keep_their_connection_while_idle_ones_are_evicted():
    with serve_in_thread(random_server(max_clients=2, first_request_timeout_s=60, evict_idle_s=0.3)) as srv:
        active = client(srv)
        active.reset(seed=0)
        stop, errors = threading.Event(), []

        def busy() -> None:
            try:
                while not stop.is_set():
                    active.infer(OBS)
                    time.sleep(0.02)
            except Exception as exc:
                errors.append(exc)

        worker = threading.Thread(target=busy)
        worker.start()
        idle = raw(srv)
        time.sleep(0.5)
        newcomer = client(srv)  # evicts the idle connection, never the active one
        assert newcomer.infer(OBS)["gripper"].shape == (8, 1)
        with pytest.raises(ConnectionClosed) as closed:
            idle.recv(timeout=5)
        assert closed.value.rcvd.code == 1001
        stop.set()
        worker.join()
        assert errors == [] and active.connects == 1


def test_client_idle_between_requests_is_timed_out_and_reconnects_transparently():
    with serve_in_thread(random_server(idle_timeout_s=0.3)) as srv:
        c = client(srv)
        c.infer(OBS)
        time.sleep(0.8)  # the server has closed the idle connection by now (code 1001)
        assert c.infer(OBS)["arm"].shape == (8, 7)
        assert c.connects == 2 and srv.active == 1
