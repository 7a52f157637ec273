"""The shared-memory policy transport (issue 28 item 2): observations reach the policy as read-only
views of what the worker wrote, actions come back intact; forged or malformed messages, a client
killed mid-request and a server killed under its clients are one-line infrastructure errors (or
nothing) and leave no shared memory behind (no ``/dev/shm`` entry, no mapping once closed)."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import ClassVar

import numpy as np
import pytest

from molmo_lerobot.errors import INFRASTRUCTURE, error_kind
from molmo_lerobot.policies.base import Policy, PolicyOptions
from molmo_lerobot.protocol import shm
from molmo_lerobot.protocol.client import PolicyConnectionError, PolicyServerError
from molmo_lerobot.protocol.codec import CodecError
from molmo_lerobot.serving.run_server import ServeError, serve_transport
from molmo_lerobot.serving.server import PolicyServer, serve_in_thread
from molmo_lerobot.serving.shm_server import ShmPolicyServer

pytestmark = pytest.mark.skipif(not shm.available(), reason="needs Linux memfd with seals")
SRC = os.path.join(os.path.dirname(__file__), "..", "..", "src")
META = {"server": "molmo-serve"}
RESET = {"episode_index": 0, "seed": 1, "prompt": "p", "move_groups": {"arm": 7, "gripper": 1}, "policy_dt_s": 0.066}


class Echo(Policy):
    """Acts with the mean of each image channel (so the reply depends on every pixel) and the qpos;
    remembers what it was handed."""

    seen: ClassVar[list[dict]] = []

    def reset(self, ctx):
        self.seed = ctx.seed

    def act(self, obs):
        Echo.seen.append(obs)
        if obs.get("step") == "slow":
            time.sleep(1.0)
        img = obs["images"]["cam"]
        return {"arm": np.concatenate([img.reshape(-1, 3).mean(0), obs["qpos"]["arm"][:4]]),
                "gripper": np.array([float(self.seed)])}


def observation(rng, step=0):
    return {"images": {"cam": rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)},
            "qpos": {"arm": rng.normal(size=7), "gripper": np.array([0.5], np.float32)}, "prompt": "p", "step": step}


def memfd_maps() -> list[str]:
    with open("/proc/self/maps") as f:
        return [line for line in f if "memfd:molmo-" in line]


@pytest.fixture
def server():
    Echo.seen = []
    with serve_in_thread(ShmPolicyServer(Echo, metadata=META, first_request_timeout_s=30)) as srv:
        yield srv


def test_observations_arrive_as_read_only_views_and_actions_come_back(server):
    rng = np.random.default_rng(0)
    before = set(os.listdir("/dev/shm"))
    with shm.ShmPolicyClient(server.address, timeout_s=10) as client:
        assert client.metadata["server"] == "molmo-serve"
        client.reset(**RESET)
        for step in range(5):  # more steps than ring frames: each request its own frame
            obs = observation(rng, step)
            action = client.infer(obs)
            seen = Echo.seen[-1]
            np.testing.assert_array_equal(seen["images"]["cam"], obs["images"]["cam"])
            assert not seen["images"]["cam"].flags.writeable and seen["qpos"]["gripper"].dtype == np.float32
            assert seen["prompt"] == "p" and seen["step"] == step
            np.testing.assert_array_equal(action["arm"][:3], obs["images"]["cam"].reshape(-1, 3).mean(0))
            assert action["gripper"].tolist() == [1.0] and action["arm"].flags.writeable  # a copy of its own
            assert set(action) == {"arm", "gripper", "server_timing"}
        obs = observation(rng, 5)
        obs["images"]["cam"] = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)  # outgrows the segment
        np.testing.assert_array_equal(client.infer(obs)["arm"][:3], obs["images"]["cam"].reshape(-1, 3).mean(0))
        with pytest.raises(CodecError, match="refusing dtype '<c16'"):  # the dtype whitelist, before anything is sent
            client.infer({**obs, "qpos": {"arm": np.zeros(7, complex)}})
    Echo.seen.clear()
    deadline = time.monotonic() + 5
    while (server.active or memfd_maps()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert server.active == 0 and server.served == 6
    assert memfd_maps() == [] and set(os.listdir("/dev/shm")) <= before


def raw_client(server) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    sock.settimeout(10)
    sock.connect(shm.sock_address(server.address))
    assert shm.parse(*socket.recv_fds(sock, shm.MAX_HEADER_BYTES, 1)[:3])[0]["server"] == "molmo-serve"
    return sock


def answer(sock) -> dict:
    return shm.parse(*socket.recv_fds(sock, shm.MAX_HEADER_BYTES, 1)[:3])[0]


@pytest.mark.parametrize(("forge", "reason"), [
    (lambda tree: tree, "observation before its shared memory segment"),
    (lambda tree: {**tree, "images": {"cam": {"__shm__": [0, "|O", [4, 4, 3]]}}}, "refusing dtype '\\|O'"),
    (lambda tree: {**tree, "images": {"cam": {"__shm__": [1 << 30, "|u1", [4, 4, 3]]}}}, "outside the"),
    (lambda tree: {**tree, "images": {"cam": {"__shm__": [0, "|u1", [4, -4, 3]]}}}, "non-negative ints"),
    (lambda tree: {**tree, "images": {"cam": {"__shm__": [0, "|u1", [4, 4]]}}}, r"images\['cam'\] must be a 3-d"),
])
def test_forged_messages_are_refused_for_that_client_only(server, forge, reason):
    rng = np.random.default_rng(1)
    segment = shm.Segment("test", shm.RING)
    tree = segment.write(observation(rng), 1)
    bad = raw_client(server)
    shm.send(bad, {"obs": forge(tree), "frame": 1}, None if "before" in reason else segment.fd)
    reply = answer(bad)
    assert reply["kind"] == "request" and len(reply["error"].splitlines()) == 1
    assert re.search(reason, reply["error"])
    assert bad.recv(16) == b""  # and the connection is closed
    with shm.ShmPolicyClient(server.address, timeout_s=10) as good:  # the others are served on
        good.reset(**RESET)
        assert good.infer(observation(rng))["gripper"].tolist() == [1.0]
    segment.close()


def test_unsealed_segments_and_frames_out_of_range_are_refused(server):
    rng = np.random.default_rng(2)
    segment = shm.Segment("test", shm.RING)
    tree = segment.write(observation(rng), 0)
    sock = raw_client(server)
    shm.send(sock, {"obs": tree, "frame": shm.RING}, segment.fd)
    assert "frame must be an integer in [0, 2)" in answer(sock)["error"]
    unsealed = os.memfd_create("plain")
    os.ftruncate(unsealed, 2 * segment.frame_bytes)
    sock = raw_client(server)
    shm.send(sock, {"obs": tree, "frame": 0}, unsealed)
    assert "not sealed against shrinking" in answer(sock)["error"]
    os.close(unsealed)
    segment.close()


def test_a_refusal_reaches_the_client_as_one_line_infrastructure_error(server):
    with shm.ShmPolicyClient(server.address, timeout_s=10) as client:
        with pytest.raises(shm.ShmTransportError, match=r"failed: RequestError: images\['cam'\] must be") as err:
            client.infer({"images": {"cam": np.zeros((4, 4), np.uint8)}})
        assert error_kind(err.value) == INFRASTRUCTURE and "\n" not in str(err.value)
        assert not client.connected


def test_a_failing_policy_is_the_episode_error_as_over_websockets(server):
    with shm.ShmPolicyClient(server.address, timeout_s=10) as client:
        client.reset(**RESET)
        with pytest.raises(PolicyServerError, match="KeyError: 'images'") as err:
            client.infer({"qpos": {"arm": np.zeros(7)}})
        assert error_kind(err.value) != INFRASTRUCTURE


CLIENT = """
import sys, numpy as np
from molmo_lerobot.protocol.shm import ShmPolicyClient
c = ShmPolicyClient(sys.argv[1], timeout_s=30)
c.connect()
print("connected", flush=True)
c.infer({"images": {"cam": np.zeros((8, 8, 3), np.uint8)}, "qpos": {"arm": np.zeros(7)}, "step": "slow"})
"""


def test_a_client_killed_mid_request_frees_its_slot_and_memory(server):
    proc = subprocess.Popen([sys.executable, "-c", CLIENT, server.address], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": SRC})
    assert proc.stdout.readline().strip() == "connected"
    deadline = time.monotonic() + 20
    while not Echo.seen and time.monotonic() < deadline:
        time.sleep(0.02)
    assert Echo.seen and memfd_maps()  # the server maps the client's segment while the policy acts
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    proc.stdout.close()
    Echo.seen.clear()
    while (server.active or memfd_maps()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert server.active == 0 and memfd_maps() == []


SERVER = """
import sys, numpy as np
from molmo_lerobot.policies.random_policy import RandomPolicy
from molmo_lerobot.serving.shm_server import ShmPolicyServer
ShmPolicyServer(lambda: RandomPolicy({}), address=sys.argv[1]).run(ready=lambda s: print("ready", flush=True))
"""


def test_a_server_killed_under_its_client_is_a_one_line_infrastructure_error():
    address = shm.new_address()
    proc = subprocess.Popen([sys.executable, "-c", SERVER, address], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": SRC})
    try:
        assert proc.stdout.readline().strip() == "ready"
        client = shm.ShmPolicyClient(address, timeout_s=10, connect_timeout_s=0.5, backoff_s=0.1)
        client.connect()
        client.reset(**RESET)
        assert set(client.infer({"qpos": {"arm": np.zeros(7)}})) == {"arm", "gripper", "server_timing"}
        assert memfd_maps()  # the client maps the server's action segment
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
    with pytest.raises(PolicyConnectionError, match=r"policy server shm\+unix:@molmo-serve-") as err:
        client.infer({"qpos": {"arm": np.zeros(7)}})
    assert error_kind(err.value) == INFRASTRUCTURE and "\n" not in str(err.value)
    client.__exit__()
    assert memfd_maps() == [] and not [n for n in os.listdir("/dev/shm") if "molmo" in n]


def _impostor(address: str, ready_w: int, report_w: int) -> None:
    """Forked child: as user ``nobody``, listen on ``address``, greet the first client with an empty
    metadata map (what a client that does not check would take) and report how many bytes it sent."""
    got = -1
    try:
        os.setgid(65534)
        os.setuid(65534)
        with socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET) as srv:
            srv.bind(shm.sock_address(address))
            srv.listen(1)
            os.write(ready_w, b"r")
            srv.settimeout(60)
            conn, _ = srv.accept()
            conn.settimeout(10)
            try:
                conn.send(b"\x80")
                got = len(conn.recv(1 << 16))
            except OSError:  # the client hung up first
                got = 0
    finally:
        os.write(report_w, str(got).encode())
        os._exit(0)


@pytest.mark.skipif(os.geteuid() != 0, reason="runs a server as another user (needs root)")
def test_a_client_refuses_a_server_of_another_user_before_sending_anything():
    """Issue 39, defect 2: abstract names are visible to every local user. A client (re)connecting
    while its server is gone reaches whatever listens on the name: one of another user's is refused,
    with nothing sent (a request connects lazily, as after a dropped connection)."""
    address = shm.new_address()
    client = shm.ShmPolicyClient(address, timeout_s=10, connect_timeout_s=5, backoff_s=0.1)
    ready_r, ready_w = os.pipe()
    report_r, report_w = os.pipe()
    pid = os.fork()
    if pid == 0:
        _impostor(address, ready_w, report_w)
    os.close(ready_w)
    os.close(report_w)
    try:
        assert os.read(ready_r, 1) == b"r", "the impostor did not start"
        with pytest.raises(shm.ShmTransportError) as err:
            client.infer(observation(np.random.default_rng(0)))
        assert re.fullmatch(rf"policy server shm\+unix:{address} \(process {pid}\) runs as user 65534, not as "
                            rf"this process's user 0: refused, nothing sent", str(err.value)), str(err.value)
        assert error_kind(err.value) == INFRASTRUCTURE
        assert os.read(report_r, 32) == b"0", "the client sent the impostor something"
        assert not client.connected
    finally:
        os.waitpid(pid, 0)
        os.close(ready_r)
        os.close(report_r)
        client.close()


def test_serve_transport_auto_is_shm_for_the_local_executor_only():
    def policy(**keys):
        return PolicyOptions(name="any", **keys)

    assert serve_transport(policy(serve_transport="auto"), "local") == "shm"
    assert serve_transport(policy(), "ray") == "websocket"
    assert serve_transport(policy(serve_transport="websocket"), "local") == "websocket"
    with pytest.raises(ServeError, match="serve_transport=shm needs executor=local"):
        serve_transport(policy(serve_transport="shm"), "ray")


def test_clients_in_step_are_batched_as_over_websockets():
    """Both transports share the batcher: two clients in step are answered in one batch."""

    class Batched(Echo):
        batched = True

        @classmethod
        def act_batch(cls, policies, observations):
            return [p.act(o) for p, o in zip(policies, observations, strict=True)]

    with serve_in_thread(ShmPolicyServer(Batched, metadata=META, max_batch=2, batch_timeout_ms=2000)) as srv:
        assert isinstance(srv, PolicyServer)
        barrier = threading.Barrier(2)

        def run(seed):
            with shm.ShmPolicyClient(srv.address, timeout_s=20) as client:
                client.reset(**{**RESET, "seed": seed})
                barrier.wait()
                for step in range(3):
                    assert client.infer(observation(np.random.default_rng(seed), step))["gripper"] == [seed]

        threads = [threading.Thread(target=run, args=(s,)) for s in (1, 2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        deadline = time.monotonic() + 10  # the server counts a reply once it is sent: just after the client has it
        while srv.served < 6 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert srv.served == 6 and srv.stats()["batch_sizes"].get("2", 0) >= 1


@pytest.mark.parametrize("shape", [[1 << 32, 1 << 32], [1 << 62, 4], [0, 1 << 70], [3, 1 << 61, 8]])
def test_a_shape_whose_size_would_wrap_is_a_transport_error(shape):
    """int64 products of these shapes wrap to 0 or a small number: the size is checked without wrapping."""
    import mmap

    buf = mmap.mmap(-1, 64)
    with pytest.raises(shm.ShmTransportError, match=r"does not fit the 64-byte frame|outside the 64-byte frame"):
        shm._views({"__shm__": [0, "<f8", shape]}, buf, 0, 64)
    buf.close()
