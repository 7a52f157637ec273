"""Worker memory over long runs: a worker's resident memory (and its LIBERO env server's), sampled every 2 s.

``molmo-eval ... workers=1`` runs in a fresh process; a sampler reads ``VmRSS`` of every process under it (the
worker is the fork server's child, a LIBERO env server the worker's) and counts the episodes finished so far
(``episodes.jsonl``). Each row reports the peak, the slope over the run's second half (MB per episode, least
squares) and the growth over its last five episodes (their peak over the peak before them). Report, not assert;
rows go to ``runs/perf.jsonl``.

* ``pick_v3`` over ``MOLMO_PERF_MEMORY_HOUSES`` (default 40) houses, recorded: pick_v3's episodes reordered house
  after house (the first of each of its 20 houses, then the second, ...), so every episode loads a house the
  4-model cache no longer holds;
* ``libero_object``, recorded, one episode of each of ``MOLMO_PERF_MEMORY_TASKS`` (default 6) tasks, ``policy=random``.

``MOLMO_PERF_MEMORY_RECORD=false`` runs both unrecorded; ``MOLMO_PERF_MEMORY_HORIZON=K`` cuts pick_v3's episodes to K
steps (the houses loaded, and so the model cache's turnover, stay the same).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from perf_rows import append_rows

from molmo_lerobot.suites.libero import libero_venv

pytestmark = pytest.mark.perf

EVERY_S = 2.0


def _children() -> dict[int, list[int]]:
    tree: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError):
                continue
            tree.setdefault(ppid, []).append(int(entry.name))
    return tree


def _rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def _roles(root: int) -> dict[str, int]:
    """``worker`` (the fork server's child) and ``suite`` (the LIBERO env server) under ``root``."""
    tree, roles, todo = _children(), {}, [root]
    while todo:
        pid = todo.pop()
        for child in tree.get(pid, []):
            try:
                cmd = Path(f"/proc/{child}/cmdline").read_bytes().decode(errors="replace")
            except OSError:
                continue
            if "libero_server" in cmd:
                roles["suite"] = child
            elif "forkserver" in Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace"):
                roles["worker"] = child
            todo.append(child)
    return roles


def sampled_run(args: list[str], out: Path) -> list[dict[str, Any]]:
    """Run ``molmo-eval ARGS workers=1 output_dir=OUT``; samples ``{t, episodes, worker, suite}`` (MB)."""
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "HF_HUB_OFFLINE": "1"}
    err = out.parent / f"{out.name}.stderr"
    proc = subprocess.Popen([sys.executable, "-m", "molmo_lerobot.cli.eval", *args, "workers=1",
                             f"output_dir={out}", "progress=false"], env=env, stdout=subprocess.DEVNULL,
                            stderr=err.open("w"))
    samples: list[dict[str, Any]] = []
    t0 = time.monotonic()
    while proc.poll() is None:
        episodes = out / "episodes.jsonl"
        done = len(episodes.read_text().splitlines()) if episodes.exists() else 0
        sample = {"t": round(time.monotonic() - t0, 1), "episodes": done}
        for role, pid in _roles(proc.pid).items():
            if (rss := _rss_mb(pid)) is not None:
                sample[role] = round(rss, 1)
        samples.append(sample)
        time.sleep(EVERY_S)
    assert proc.returncode == 0, err.read_text()[-2000:]
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert all(r["error"] is None for r in rows), [r["error"] for r in rows]
    return samples


def summary(samples: list[dict[str, Any]], role: str, n: int) -> dict[str, Any]:
    """Peak, second-half slope (MB per episode) and last-five-episode growth of ``role`` (``total``: both)."""
    points = [(s["episodes"], s.get("worker", 0.0) + s.get("suite", 0.0) if role == "total" else s[role])
              for s in samples if role == "total" or role in s]
    second = [(e, r) for e, r in points if e >= n // 2]
    slope = float(np.polyfit(*zip(*second, strict=True), 1)[0]) if len({e for e, _ in second}) > 1 else None
    before = [r for e, r in points if e < n - 5]
    last = [r for e, r in points if e >= n - 5]
    return {"role": role, "peak_mb": round(max(r for _, r in points)),
            "slope_mb_per_episode_2nd_half": None if slope is None else round(slope, 1),
            "growth_last5_mb": round(max(last) - max(before)) if before and last else None}


def _report(name: str, samples: list[dict[str, Any]], n: int, roles: tuple[str, ...], **common: Any) -> None:
    rows = [summary(samples, role, n) for role in roles]
    for row in rows:
        print(f"{name} {row['role']}: peak {row['peak_mb']} MB, second half {row['slope_mb_per_episode_2nd_half']} "
              f"MB/episode, last 5 episodes {row['growth_last5_mb']} MB over the peak before them")
    append_rows(name, rows, test="worker_memory", episodes=n, **common)


def _record() -> bool:
    return os.environ.get("MOLMO_PERF_MEMORY_RECORD", "true") == "true"


@pytest.mark.timeout(3 * 3600)
def test_pick_v3_worker_memory_over_many_houses(tmp_path):
    houses = int(os.environ.get("MOLMO_PERF_MEMORY_HOUSES", "40"))
    source = Path(__file__).parents[2] / "benchmarks" / "pick_v3"
    episodes = json.loads((source / "benchmark.json").read_text())
    by_house: dict[int, list[dict[str, Any]]] = {}
    for ep in episodes:
        by_house.setdefault(ep["house_index"], []).append(ep)
    rounds = [eps[k] for k in range(max(map(len, by_house.values()))) for eps in by_house.values() if k < len(eps)]
    bench = tmp_path / "pick_v3_houses"
    bench.mkdir()
    (bench / "benchmark.json").write_text(json.dumps(rounds[:houses]))
    metadata = json.loads((source / "benchmark_metadata.json").read_text())
    (bench / "benchmark_metadata.json").write_text(json.dumps({**metadata, "name": "pick_v3_houses",
                                                               "num_episodes": houses}))
    horizon = os.environ.get("MOLMO_PERF_MEMORY_HORIZON")
    samples = sampled_run(["policy=scripted", f"benchmark.path={bench}", f"record={str(_record()).lower()}",
                           *([f"horizon={horizon}"] if horizon else [])], tmp_path / "run")
    _report("pick_v3", samples, houses, ("worker",), record=_record(), houses=houses, horizon=horizon)


@pytest.mark.timeout(3 * 3600)
def test_libero_worker_memory_over_tasks(tmp_path):
    if not (libero_venv() / "bin" / "python").exists():
        pytest.skip(f"no LIBERO venv at {libero_venv()} (make .libero-venv)")
    tasks = int(os.environ.get("MOLMO_PERF_MEMORY_TASKS", "6"))
    samples = sampled_run(["policy=random", "benchmark=libero_object", f"limit={tasks}",
                           f"record={str(_record()).lower()}"], tmp_path / "run")
    _report("libero_object", samples, tasks, ("worker", "suite", "total"), record=_record(), tasks=tasks)
