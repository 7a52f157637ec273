"""Dynamic batching in molmo-serve (issue 17): one ``act_batch`` call for requests from different
connections; per-connection state; a slow client, a client that disconnects mid-batch and a bad
observation inside a batch each affect only their own request."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from websockets.sync.client import connect

from molmo_lerobot.policies.base import Policy
from molmo_lerobot.protocol.client import PolicyClient, PolicyServerError
from molmo_lerobot.protocol.codec import packb, unpackb
from molmo_lerobot.serving.server import PolicyServer, serve_in_thread

OBS = {"qpos": {"arm": np.zeros(7), "gripper": np.zeros(1)}}


class Batcher(Policy):
    """Counts its own calls (per-client state); records every batch it is called with."""

    batched = True
    needs_images = False

    def __init__(self, shared: dict) -> None:
        self.shared, self.count, self.episode = shared, 0, -1

    def fork(self) -> Batcher:
        return Batcher(self.shared)

    def reset(self, ctx) -> None:
        self.count, self.episode = 0, ctx.episode_index

    def act(self, obs):
        raise AssertionError("a batched server calls act_batch")

    @classmethod
    def act_batch(cls, policies, observations):
        shared = policies[0].shared
        shared["batches"].append(len(policies))
        time.sleep(shared.get("sleep", 0.0))
        if any(o.get("poison") for o in observations):
            raise RuntimeError("one item breaks the whole call")
        out = []
        for p, o in zip(policies, observations, strict=True):
            if o.get("bad"):
                out.append(ValueError("bad observation on purpose"))
                continue
            p.count += 1
            out.append({"arm": np.full((1, 7), float(p.count)), "gripper": np.full((1, 1), float(p.episode))})
        return out

    def close(self) -> None:
        self.shared["closed"] += 1


@pytest.fixture
def shared():
    return {"batches": [], "closed": 0}


def server(shared, **kw) -> PolicyServer:
    return PolicyServer(lambda: Batcher(shared), port=0, max_batch=8, **kw)


def clients(srv, n) -> list[PolicyClient]:
    out = [PolicyClient("127.0.0.1", srv.port, timeout_s=10, connect_timeout_s=5) for _ in range(n)]
    for i, c in enumerate(out):
        c.reset(episode_index=i)
    return out


def together(fns) -> list:
    """Run ``fns`` at the same moment in threads; return their results (or exceptions)."""
    barrier, results = threading.Barrier(len(fns)), [None] * len(fns)

    def run(i, fn):
        barrier.wait()
        try:
            results[i] = fn()
        except Exception as exc:
            results[i] = exc

    threads = [threading.Thread(target=run, args=(i, fn)) for i, fn in enumerate(fns)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return results


def test_requests_from_different_connections_run_as_one_call_with_per_client_state(shared):
    with serve_in_thread(server(shared, batch_timeout_ms=500)) as srv:
        cs = clients(srv, 4)
        first = together([lambda c=c: c.infer(OBS) for c in cs])
        assert shared["batches"] == [4] and srv.batching and cs[0].metadata["batched"] is True
        assert [r["gripper"][0, 0] for r in first] == [0, 1, 2, 3]  # each client's own episode
        cs[2].reset(episode_index=9)  # resets client 2 only
        second = together([lambda c=c: c.infer(OBS) for c in cs])
        assert [r["arm"][0, 0] for r in second] == [2, 2, 1, 2] and second[2]["gripper"][0, 0] == 9
        assert srv.stats()["batch_sizes"] == {"4": 2}


def test_a_slow_client_does_not_hold_back_the_others(shared):
    with serve_in_thread(server(shared, batch_timeout_ms=100)) as srv:
        fast_a, fast_b, slow = clients(srv, 3)

        def timed(c, delay):
            time.sleep(delay)
            t0 = time.monotonic()
            c.infer(OBS)
            return time.monotonic() - t0

        a, b, s = together([lambda: timed(fast_a, 0), lambda: timed(fast_b, 0), lambda: timed(slow, 1.5)])
        assert a < 1.0 and b < 1.0 and s < 1.0  # nobody waited for the slow client
        assert shared["batches"] == [2, 1]


def test_a_client_that_disconnects_mid_batch_affects_only_itself(shared):
    shared["sleep"] = 0.5
    with serve_in_thread(server(shared, batch_timeout_ms=300)) as srv:
        a, b = clients(srv, 2)
        quitter = connect(f"ws://127.0.0.1:{srv.port}", compression=None)
        unpackb(quitter.recv(timeout=5))

        def send_and_vanish():
            quitter.send(packb(OBS))
            time.sleep(0.1)  # inside the batch's 0.5 s
            quitter.close()

        ra, rb, _ = together([lambda: a.infer(OBS), lambda: b.infer(OBS), send_and_vanish])
        assert shared["batches"] == [3] and ra["arm"][0, 0] == 1 and rb["arm"][0, 0] == 1
        deadline = time.monotonic() + 5
        while shared["closed"] < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert shared["closed"] == 1 and srv.active == 2  # its fork closed after the batch
        assert a.infer(OBS)["arm"][0, 0] == 2 and a.connects == 1


def test_a_bad_observation_inside_a_batch_fails_only_its_request(shared):
    with serve_in_thread(server(shared, batch_timeout_ms=300)) as srv:
        good, bad, malformed = clients(srv, 3)
        rg, rb, rm = together([lambda: good.infer(OBS), lambda: bad.infer({**OBS, "bad": True}),
                               lambda: malformed.infer({"qpos": {"arm": np.zeros((3, 7))}})])
        assert rg["arm"][0, 0] == 1
        assert isinstance(rb, PolicyServerError) and "ValueError: bad observation on purpose" in str(rb)
        assert isinstance(rm, PolicyServerError) and "qpos['arm'] must be a 1-d" in str(rm)  # refused before batching
        assert good.infer(OBS)["arm"][0, 0] == 2 and good.connects == 1
        assert bad.infer(OBS)["arm"][0, 0] == 1  # reconnected: a fresh client


def test_a_call_that_breaks_as_a_whole_is_retried_per_item(shared):
    with serve_in_thread(server(shared, batch_timeout_ms=300)) as srv:
        a, b, c = clients(srv, 3)
        ra, rb, rc = together([lambda: a.infer(OBS), lambda: b.infer({**OBS, "poison": True}), lambda: c.infer(OBS)])
        assert ra["arm"][0, 0] == 1 and rc["arm"][0, 0] == 1
        assert isinstance(rb, PolicyServerError) and "one item breaks the whole call" in str(rb)
        assert shared["batches"] == [3, 1, 1, 1]


def test_clients_fall_into_step_and_an_idle_one_is_not_waited_for(shared):
    with serve_in_thread(server(shared, batch_timeout_ms=300)) as srv:
        a, b = clients(srv, 2)

        def episode(c, offset, steps, pause_at=-1):
            time.sleep(offset)
            latencies = []
            for i in range(steps):
                if i == pause_at:
                    time.sleep(2.0)  # e.g. building the next scene: the server must not wait for it
                t0 = time.monotonic()
                c.infer(OBS)
                latencies.append(time.monotonic() - t0)
                time.sleep(0.05)  # the client's own work between requests
            return latencies

        la, _ = together([lambda: episode(a, 0, 30), lambda: episode(b, 0.12, 8)])
        assert shared["batches"][1:7] == [2] * 6  # out of phase at first, then in step
        assert sorted(la)[len(la) // 2] < 0.1  # once b went idle, a was answered without waiting
