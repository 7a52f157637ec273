"""Per-episode wall, v3 ÷ v2, of a camera-reading policy and of a recorded scripted run (issue 36).

``pytest -m perf -s tests/perf/test_episode_wall_v3_v2.py`` (a report; nothing asserted about speed).
The same ``pick`` episodes run through ``pick_v2`` and ``pick_v3`` (the same ``benchmark.json``, render
profiles v2 and v3), one configuration after the other in each of ``MOLMO_PERF_ROUNDS`` rounds, so that a
shared machine's load falls on both alike:

* ``policy=image_scripted``: the scripted expert reading every pixel of both 224² cameras at each call
  (``MOLMO_PERF_CHUNK`` actions per call, default 4);
* ``policy=scripted record=true``: the expert recorded as a LeRobot dataset (both cameras every step).

Each run is ``molmo-eval … workers=1 limit=MOLMO_PERF_EPISODES`` (default 1) in a fresh process. The
per-episode figure is the worker's own ``duration_s`` (scene build to last step, recorder included; start-up
excluded), best over rounds; the process wall (start-up, dataset finalisation) is reported beside it.
Per-episode outcomes must be equal between v2 and v3: neither policy's actions depend on pixels.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from perf_rows import eval_run, image_policy_env

pytestmark = pytest.mark.perf
ROUNDS = int(os.environ.get("MOLMO_PERF_ROUNDS", "1"))
EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "1"))
CHUNK = int(os.environ.get("MOLMO_PERF_CHUNK", "4"))
RUNS = {"camera-reading policy": ["policy=image_scripted"], "recorded scripted run": ["policy=scripted", "record=true"]}


def _run(version: str, args: list[str], out: Path, env: dict[str, str]) -> tuple[float, list[dict]]:
    wall, _, rows = eval_run([f"benchmark=pick_{version}", *args, "workers=1", f"limit={EPISODES}", "seed=0"], out, env)
    return wall, rows


def test_episode_wall_v3_over_v2(tmp_path):
    env = image_policy_env(tmp_path / "site", CHUNK)
    walls: dict[tuple[str, str], list[float]] = {}
    episode_s: dict[tuple[str, str], list[float]] = {}
    outcomes: dict[tuple[str, str], list[tuple]] = {}
    for k in range(ROUNDS):
        for name, args in RUNS.items():
            for version in ("v2", "v3"):
                wall, rows = _run(version, args, tmp_path / f"{version}-{len(walls)}-{k}", env)
                walls.setdefault((name, version), []).append(wall)
                episode_s.setdefault((name, version), []).append(sum(r["duration_s"] for r in rows) / len(rows))
                outcomes[(name, version)] = [(r["episode_index"], r["success"], r["steps"]) for r in rows]
    table = {}
    for name in RUNS:
        assert outcomes[(name, "v2")] == outcomes[(name, "v3")], f"{name}: v2 and v3 outcomes differ"
        v2, v3 = min(episode_s[(name, "v2")]), min(episode_s[(name, "v3")])
        table[name] = {"v2_episode_s": round(v2, 2), "v3_episode_s": round(v3, 2), "v3_over_v2": round(v3 / v2, 3),
                       "v2_process_wall_s": round(min(walls[(name, "v2")]), 2),
                       "v3_process_wall_s": round(min(walls[(name, "v3")]), 2),
                       "successes": sum(o[1] for o in outcomes[(name, "v2")])}
    line = json.dumps({"benchmark": "episode_wall_v3_v2", "episodes": EPISODES, "rounds": ROUNDS, "chunk": CHUNK,
                       "cpus": os.cpu_count(), **table})
    print("\n" + line)
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        f.write(line + "\n")
