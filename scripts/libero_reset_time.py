"""Time the LIBERO server's episode resets (reset, init state, settle steps) on one task, in the LIBERO venv:

    .libero-venv/bin/python scripts/libero_reset_time.py SUITE TASK_ID IMAGE_SIZE EPISODES

Episode k starts from init state k with seed 7 + k (LeRobot's hard reset). Prints one JSON line: each reset's
seconds (the first includes building the env) and a digest of each first observation (images and state), so two
versions of the server can be compared for speed and for the bits they give.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
os.environ.setdefault("LIBERO_CONFIG_PATH", str(Path(sys.prefix) / "libero-config"))
os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.suites.libero_server import LiberoServer


def main(suite: str, task_id: int, size: int, episodes: int) -> None:
    server = LiberoServer()
    seconds, digests = [], []
    try:
        for k in range(episodes):
            start = time.perf_counter()
            obs = server.reset(suite, task_id, k, 7 + k, size, size, hard_reset=True)["observation"]
            seconds.append(round(time.perf_counter() - start, 2))
            digests.append(hashlib.sha256(b"".join(obs[key].tobytes() for key in sorted(obs))).hexdigest()[:12])
    finally:
        server.close_envs()
    print(json.dumps({"suite": suite, "task_id": task_id, "size": size, "reset_s": seconds, "first_obs": digests}))


if __name__ == "__main__":
    if len(sys.argv) != 5:
        raise SystemExit(__doc__)
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))
