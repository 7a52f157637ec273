"""Worker start-up, spawn against the preloaded fork server (issue 28 item 1): where each worker's
start-up goes, from one run of each.

Both start methods run the same ``molmo-eval`` (its CLI, in a fresh process) on the same episodes of
``pick_v1`` with ``W`` workers and one short episode per worker, for two policies: the scripted
expert (MuJoCo and the harness only) and a tiny ACT at random init (torch and LeRobot too; on
``MOLMO_PERF_DEVICE``). Each worker times its own phases (``results.json``'s ``startup``):
``launch_s`` (process start; for spawn also the imports of unpickling its job), ``imports_s`` (the
modules a fork server preloads), ``context_s``, ``policy_s``, and in its first episode
``first_scene_s`` (scene built, compiled, reset) and ``renderer_s`` (OpenGL/EGL contexts);
``ready_s`` sums the phases before the first episode. The medians over workers are printed with
the run's wall time and the ratios spawn / forkserver; per-episode outcomes are asserted equal.

``pytest -m perf -s tests/perf/test_worker_startup.py``; knobs ``MOLMO_PERF_STARTUP_WORKERS`` (2),
``MOLMO_PERF_STARTUP_POLICIES`` (``scripted,tiny_act``), ``MOLMO_PERF_HORIZON`` (5 steps),
``MOLMO_PERF_DEVICE`` (auto). Rows go to ``runs/perf.jsonl``; nothing is asserted about speed.
With a fork server the first worker's ``launch_s`` includes waiting for the server's imports, the
others' do not: the per-worker figures are in the rows.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("torch")
from test_lerobot_policy import save_tiny_act

pytestmark = pytest.mark.perf
WORKERS = int(os.environ.get("MOLMO_PERF_STARTUP_WORKERS", "2"))
HORIZON = int(os.environ.get("MOLMO_PERF_HORIZON", "5"))
DEVICE = os.environ.get("MOLMO_PERF_DEVICE", "auto")
POLICIES = os.environ.get("MOLMO_PERF_STARTUP_POLICIES", "scripted,tiny_act").split(",")
METHODS = ("spawn", "forkserver")
SHOWN = ("launch_s", "imports_s", "context_s", "policy_s", "first_scene_s", "renderer_s", "ready_s", "total_s")


def _run(policy: list[str], method: str, out: Path) -> tuple[float, dict, list]:
    args = [*policy, "benchmark=pick_v1", f"limit={WORKERS}", f"horizon={HORIZON}", f"workers={WORKERS}",
            f"executor.start_method={method}", f"output_dir={out}", "progress=false"]
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.eval", *args], capture_output=True, text=True,
                          env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}, timeout=1800)
    wall = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads((out / "results.json").read_text())
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    outcomes = sorted((r["episode_index"], r["success"], r["success_once"], r["steps"], r["error"]) for r in rows)
    return wall, summary["startup"], outcomes


def test_worker_startup_spawn_vs_forkserver(tmp_path):
    act = save_tiny_act(tmp_path / "act", image_hw=(224, 224))
    policies = {
        "scripted": ["policy=scripted"],
        "tiny_act": ["policy=lerobot", f"policy.path={act}", f"policy.device={DEVICE}", "policy.mode=chunk",
                     "+policy.cameras.exterior=observation.images.front"],
    }
    lines, records = [], []
    for name, policy in ((n, policies[n]) for n in POLICIES):
        figures, outcomes = {}, {}
        for method in METHODS:
            wall, startup, outcomes[method] = _run(policy, method, tmp_path / f"{name}-{method}")
            figures[method] = {"wall_s": round(wall, 2), **startup["median"]}
            records.append({"benchmark": "worker_startup", "policy": name, "start_method": method,
                            "workers": WORKERS, "horizon": HORIZON, "device": DEVICE, "wall_s": round(wall, 2),
                            "median": startup["median"], "workers_startup": startup["workers"]})
        assert outcomes["spawn"] == outcomes["forkserver"], f"{name}: outcomes differ between start methods"
        for method in METHODS:
            lines.append(f"{name:>9} {method:>10} {figures[method]['wall_s']:>7.2f} "
                         + " ".join(f"{figures[method].get(k, 0.0):>8.3f}" for k in SHOWN))
        ratio = {k: round(figures["spawn"][k] / figures["forkserver"][k], 2)
                 for k in ("wall_s", "ready_s", "total_s") if figures["forkserver"].get(k)}
        lines.append(f"{name:>9} {'spawn/fork':>10} " + "  ".join(f"{k} {v:.2f}x" for k, v in ratio.items()))
        records.append({"benchmark": "worker_startup_ratio", "policy": name, "workers": WORKERS, "device": DEVICE,
                        **{f"spawn_over_forkserver_{k}": v for k, v in ratio.items()}})
    print(f"\nworker start-up, median over {WORKERS} workers (s), pick_v1, {HORIZON}-step episodes, "
          f"device={DEVICE}")
    print(f"{'policy':>9} {'start':>10} {'wall':>7} " + " ".join(f"{k[:-2]:>8}" for k in SHOWN))
    print("\n".join(lines))
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        for record in records:
            f.write(json.dumps(record) + "\n")
