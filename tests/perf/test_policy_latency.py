"""Policy call latency: in process vs through the websocket server (run with ``make perf``).

Same observation (two 224x224 RGB cameras + joint state) and the same policy class both ways;
the server runs in this process on 127.0.0.1, so the difference is the protocol: msgpack
encoding, the websocket round trip and the server's thread hop.
"""

from __future__ import annotations

import statistics
import time

import numpy as np
import pytest

from molmo_lerobot.policies.base import EpisodeContext, Policy
from molmo_lerobot.protocol.client import PolicyClient
from molmo_lerobot.serving.server import PolicyServer, serve_in_thread

pytestmark = pytest.mark.perf


CTX = EpisodeContext(spec=None, episode_index=0, seed=0, prompt="pick", move_groups={"arm": 7, "gripper": 1},
                     policy_dt_s=0.066)


class EchoPolicy(Policy):
    """Returns a 10-step chunk: measures pure protocol overhead."""

    def reset(self, ctx) -> None:
        pass

    def act(self, obs):
        q = np.asarray(obs["qpos"]["arm"])
        return {"arm": np.repeat(q[None], 10, 0), "gripper": np.zeros((10, 1))}


def observation(rng) -> dict:
    return {
        "images": {c: rng.integers(0, 255, (224, 224, 3), dtype=np.uint8) for c in ("exterior", "wrist")},
        "qpos": {"arm": rng.normal(size=7), "gripper": np.array([0.2])},
        "prompt": "pick the mug",
    }


def timed(fn, obs, n) -> list[float]:
    fn(obs)  # warm-up
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn(obs)
        out.append(1000 * (time.perf_counter() - t0))
    return out


def compare(make_policy, n: int) -> tuple[float, float]:
    rng = np.random.default_rng(0)
    obs = observation(rng)
    local = make_policy()
    local.reset(CTX)
    with serve_in_thread(PolicyServer(make_policy, port=0)) as srv:
        client = PolicyClient("127.0.0.1", srv.port, timeout_s=30)
        client.reset(prompt="pick")
        in_process, remote = [], []
        for _ in range(n):  # interleaved, so load from other processes hits both alike
            in_process += timed(local.act, obs, 1)
            remote += timed(client.infer, obs, 1)
        client.close()
    return statistics.median(in_process), statistics.median(remote)


def test_latency_echo_policy():
    local, remote = compare(EchoPolicy, 200)
    print(f"\necho policy, 2x224x224 cams: in-process {local:.3f} ms, server {remote:.3f} ms "
          f"(+{remote - local:.2f} ms per call)")


def test_latency_tiny_act(tmp_path):
    pytest.importorskip("torch")
    from test_lerobot_policy import save_tiny_act

    from molmo_lerobot.policies.lerobot_policy import LeRobotPolicy

    path = save_tiny_act(tmp_path / "act", image_hw=(224, 224))
    cfg = {"name": "lerobot", "path": path, "device": "cpu", "mode": "chunk",
           "cameras": {"exterior": "observation.images.front"}}
    local, remote = compare(lambda: LeRobotPolicy(cfg), 30)
    print(f"\ntiny ACT (CPU, chunk of 4): in-process {local:.2f} ms, server {remote:.2f} ms "
          f"(+{remote - local:.2f} ms per call)")
