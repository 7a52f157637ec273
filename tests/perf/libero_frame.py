"""LIBERO's frame and Gymnasium step cost, for ``test_render_profiles.py``: run with the LIBERO venv's Python.

``python tests/perf/libero_frame.py <n_steps>`` builds LeRobot's ``LiberoEnv`` on ``libero_object`` task 0
(224², the agent-view and wrist cameras, as the issue measured), then prints one JSON line: median ms
per frame of each camera (MuJoCo render + readback through robosuite's renderer, after a warm-up), wall
clock and CPU time of the process (llvmpipe's threads included), and
Gymnasium steps/s (zero actions, each step returning both camera images). ``LIBERO_CONFIG_PATH`` must
name a directory whose ``config.yaml`` points LIBERO at its assets (the test writes one)."""

from __future__ import annotations

import json
import statistics
import sys
import time

import numpy as np
from lerobot.envs.libero import LiberoEnv
from libero.libero import benchmark


def main(n_steps: int) -> None:
    suite = benchmark.get_benchmark_dict()["libero_object"]()
    env = LiberoEnv(suite, task_id=0, task_suite_name="libero_object", observation_width=224,
                    observation_height=224, obs_type="pixels_agent_pos")
    env.reset(seed=0)
    sim = env._env.sim
    frames: dict[str, float] = {}
    cpu: dict[str, float] = {}
    for cam in ("agentview", "robot0_eye_in_hand"):
        sim.render(camera_name=cam, width=224, height=224)
        times, cpus = [], []
        for _ in range(10):
            t, c = time.perf_counter(), time.process_time()
            sim.render(camera_name=cam, width=224, height=224)
            times.append(time.perf_counter() - t)
            cpus.append(time.process_time() - c)
        frames[cam] = statistics.median(times) * 1000
        cpu[cam] = statistics.median(cpus) * 1000
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    env.step(action)
    t = time.perf_counter()
    for _ in range(n_steps):
        env.step(action)
    rate = n_steps / (time.perf_counter() - t)
    print(json.dumps({"frame_ms": frames, "frame_cpu_ms": cpu, "steps_per_s": rate}))


if __name__ == "__main__":
    main(int(sys.argv[1]))
