"""What a served request costs on each transport (issue 28 item 2), the policy taken out: round trips
of an observation (one 224² RGB camera, 7+1 joint positions, a prompt) to a server whose policy
answers at once, over websockets + msgpack and over shared memory, one client, the server a
process of its own (as ``policy.serve=true`` runs it). Reports the median and 90th percentile per round trip and
their ratio; nothing is asserted about speed.

``pytest -m perf -s tests/perf/test_transport_latency.py``; knobs: ``MOLMO_PERF_REQUESTS`` (500),
``MOLMO_PERF_IMAGE_SIDE`` (224), ``MOLMO_PERF_CAMERAS`` (1). Rows are appended to ``runs/perf.jsonl``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest
from perf_rows import append_rows

from molmo_lerobot.protocol import shm
from molmo_lerobot.protocol.client import PolicyClient

pytestmark = [pytest.mark.perf, pytest.mark.skipif(not shm.available(), reason="needs Linux memfd")]
REQUESTS = int(os.environ.get("MOLMO_PERF_REQUESTS", "500"))
SIDE = int(os.environ.get("MOLMO_PERF_IMAGE_SIDE", "224"))
CAMERAS = int(os.environ.get("MOLMO_PERF_CAMERAS", "1"))
SERVER = """
import sys, numpy as np
from molmo_lerobot.policies.base import Policy
from molmo_lerobot.serving.server import PolicyServer
from molmo_lerobot.serving.shm_server import ShmPolicyServer

class Instant(Policy):  # a chunk of 4 at once, after touching one pixel of each image (so it reads them)
    def reset(self, ctx):
        pass

    def act(self, obs):
        touched = sum(int(img[0, 0, 0]) for img in obs["images"].values())
        return {"arm": np.full((4, 7), touched, np.float32), "gripper": np.zeros((4, 1), np.float32)}

meta = {"server": "molmo-serve"}
srv = ShmPolicyServer(Instant, metadata=meta) if sys.argv[1] == "shm" else PolicyServer(Instant, metadata=meta, port=0)
srv.run(ready=lambda s: print(getattr(s, "address", s.port), flush=True))
"""


def served(transport: str):
    """A client of a server process of ``transport``; the server is killed when the client is done."""
    proc = subprocess.Popen([sys.executable, "-c", SERVER, transport], stdout=subprocess.PIPE, text=True)
    where = proc.stdout.readline().strip()
    client = shm.ShmPolicyClient(where) if transport == "shm" else PolicyClient(port=int(where))
    client.connect()
    return proc, client


def round_trips(client) -> np.ndarray:
    rng = np.random.default_rng(0)
    obs = {"images": {f"cam{i}": rng.integers(0, 256, (SIDE, SIDE, 3), dtype=np.uint8) for i in range(CAMERAS)},
           "qpos": {"arm": rng.normal(size=7), "gripper": np.zeros(1)}, "prompt": "pick up the mug", "step": 0}
    client.reset(episode_index=0, seed=0, prompt="pick up the mug")
    for _ in range(20):  # warm up
        client.infer(obs)
    times = np.empty(REQUESTS)
    for i in range(REQUESTS):
        obs["step"] = i
        t0 = time.perf_counter()
        client.infer(obs)
        times[i] = time.perf_counter() - t0
    return times * 1e6


def test_round_trip_websocket_vs_shared_memory():
    results = {}
    for transport in ("websocket", "shm"):
        proc, client = served(transport)
        try:
            results[transport] = round_trips(client)
        finally:
            client.close()
            proc.terminate()
            proc.wait(30)
            proc.stdout.close()
    mb = CAMERAS * SIDE * SIDE * 3 / 1e6
    print(f"\nround trip of {CAMERAS} x {SIDE}² RGB ({mb:.2f} MB) + state, {REQUESTS} requests, instant policy")
    rows = []
    for name, us in results.items():
        rows.append({"transport": name, "median_us": round(float(np.median(us)), 1),
                     "p90_us": round(float(np.percentile(us, 90)), 1)})
        print(f"{name:>10}: median {rows[-1]['median_us']:8.1f} us   p90 {rows[-1]['p90_us']:8.1f} us")
    ratio = rows[0]["median_us"] / rows[1]["median_us"]
    print(f"websocket / shm (median): {ratio:.2f}x")
    append_rows("transport_latency", rows, image_side=SIDE, cameras=CAMERAS, requests=REQUESTS)
