"""Fair harness timings, measured in one run: ``pytest -m perf -s tests/perf/test_harness_overhead.py``.

Both sides run in fresh processes and do the same work on the same episodes of ``pick_v1``:
the same scene build (``build_env``), the same ``reset``/``observe``/``step`` calls with the same
renders (the policy consumes both 224² camera images at every call, so rendering is part of
both), the same policy calls, the same seeds and horizons. The raw side is a bare loop in one
process; the harness side is ``molmo-eval`` (plugins, validation, worker processes, supervision,
result files). Per-episode outcomes are asserted identical.

Each side is timed for ``M`` and ``N`` episodes: per-episode cost = (T_N - T_M) / (N - M), fixed
cost (interpreter start, imports, plugin and policy loading, worker start-up, result files) =
T_M - M x per-episode. Each episode's own time (scene build to last step: the raw loop's clock,
the worker's ``duration_s``) is reported too, and the same split on CPU seconds (each process
and every descendant it reaped: workers included), both far less noisy than walls on a shared
machine. The configurations run interleaved, ``REPS`` times; the best of each is kept. The same
is done for ``molmo-eval`` with 2 workers (throughput workers=2 / workers=1).

Figures are printed and appended to ``runs/perf.jsonl``; nothing is asserted about speed.
Knobs: ``MOLMO_PERF_EPISODES`` (N, default 6; M = N / 3), ``MOLMO_PERF_HORIZON`` (policy steps,
default 40), ``MOLMO_PERF_CHUNK`` (actions per policy call, default 4), ``MOLMO_PERF_REPS`` (3).
"""

from __future__ import annotations

import json
import os
import sys
import textwrap
from pathlib import Path

import pytest
from perf_rows import eval_run, image_policy_env, timed

pytestmark = pytest.mark.perf
N = max(2, int(os.environ.get("MOLMO_PERF_EPISODES", "6")))
M = max(1, N // 3)
HORIZON = int(os.environ.get("MOLMO_PERF_HORIZON", "40"))
CHUNK = int(os.environ.get("MOLMO_PERF_CHUNK", "4"))
REPS = int(os.environ.get("MOLMO_PERF_REPS", "3"))
BENCHMARK = "pick_v1"

#: The raw loop, run as ``python -c RAW '{"n": …}'``: prints one JSON line of outcomes.
RAW = textwrap.dedent('''
    import json, sys, time
    from collections import deque

    import numpy as np

    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.paths import data_path
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.policies.base import EpisodeContext
    from molmo_lerobot.runner.plan import episode_seed
    from molmo_lerobot.runner.episode_env import build_env
    from molmo_lerobot.sim.env import Timing
    from molmo_perf_policies import ImageScripted

    args = json.loads(sys.argv[1])
    run = RunContext.build()
    plugins = run.plugins
    bench = load_benchmark(data_path("benchmarks") / args["benchmark"], plugins)
    timing = Timing()
    policy = ImageScripted({"name": "image_scripted", "chunk": args["chunk"]})
    out = []
    for i in range(args["n"]):
        t0 = time.perf_counter()
        spec = bench.episodes[i]
        seed = episode_seed(0, spec.model_dump(mode="json"))
        task_type = plugins.task_type(spec.task_name)
        env = build_env(spec, timing, run)
        env.reset(seed)
        task = task_type.create(spec, env)
        prompt = spec.language.task_description if spec.language else ""
        policy.reset(EpisodeContext(spec=spec, episode_index=i, seed=seed, prompt=prompt,
                                    move_groups=dict(env.move_groups), policy_dt_s=timing.policy_dt_ms / 1000.0,
                                    env=env, catalog=run.catalog, expert=run.plugins.expert(task_type.name)))
        task.setup()
        obs = env.observe(images=True)
        obs["prompt"], obs["step"] = prompt, 0
        queue = deque()
        success = success_once = False
        for step in range(args["horizon"]):
            if not queue:
                chunk = {g: np.atleast_2d(np.asarray(a, dtype=np.float64)) for g, a in policy.act(obs).items()}
                queue.extend({g: a[t] for g, a in chunk.items()} for t in range(len(next(iter(chunk.values())))))
            env.step(queue.popleft())
            success = bool(task.success())
            success_once |= success
            if step < args["horizon"] - 1:
                obs = env.observe(images=not queue)
                obs["prompt"], obs["step"] = prompt, step + 1
        env.close()
        out.append({"episode_index": i, "success": success, "success_once": success_once, "steps": args["horizon"],
                    "duration_s": time.perf_counter() - t0})
    print(json.dumps(out))
''')


@pytest.fixture(scope="module")
def perf_env(tmp_path_factory) -> dict[str, str]:
    return image_policy_env(tmp_path_factory.mktemp("site"), CHUNK)


def _raw(n: int, env: dict[str, str]) -> tuple[float, float, list[dict]]:
    args = json.dumps({"n": n, "horizon": HORIZON, "chunk": CHUNK, "benchmark": BENCHMARK})
    wall, cpu, stdout = timed([sys.executable, "-c", RAW, args], env)
    return wall, cpu, json.loads(stdout.strip().splitlines()[-1])


def _harness(n: int, workers: int, out_dir: Path, env: dict[str, str]) -> tuple[float, float, list[dict]]:
    return eval_run([f"benchmark={BENCHMARK}", "policy=image_scripted", f"limit={n}", f"horizon={HORIZON}",
                     f"workers={workers}"], out_dir, env)


def _split(t_m: float, t_n: float) -> tuple[float, float]:
    """(per-episode, fixed) seconds from the walls of M and N episodes."""
    per = (t_n - t_m) / (N - M)
    return per, t_m - M * per


def _report(name: str, figures: dict) -> None:
    line = json.dumps({"benchmark": name, **figures})
    print("\n" + line)
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        f.write(line + "\n")


def test_harness_vs_raw_loop_and_workers_scaling(perf_env, tmp_path):
    runs = {"raw": lambda n, k: _raw(n, perf_env),
            "harness_w1": lambda n, k: _harness(n, 1, tmp_path / f"w1-{n}-{k}", perf_env),
            "harness_w2": lambda n, k: _harness(n, 2, tmp_path / f"w2-{n}-{k}", perf_env)}
    keys = ("episode_index", "success", "success_once", "steps")
    walls: dict[tuple[str, int], list[float]] = {}
    cpus: dict[tuple[str, int], list[float]] = {}
    outcomes: dict[tuple[str, int], list[dict]] = {}
    episode_s: dict[tuple[str, int], float] = {}  # best time of each episode inside its process
    for k in range(REPS):  # interleaved: every configuration once per round
        for n in (M, N):
            for name, run in runs.items():
                wall, cpu, rows = run(n, k)
                walls.setdefault((name, n), []).append(wall)
                cpus.setdefault((name, n), []).append(cpu)
                seen = [{key: r[key] for key in keys} for r in rows]
                assert outcomes.setdefault((name, n), seen) == seen, f"{name} is not deterministic"
                for r in rows:
                    episode_s[(name, r["episode_index"])] = min(episode_s.get((name, r["episode_index"]), 1e9),
                                                                r["duration_s"])
    for name in runs:
        assert outcomes[(name, N)] == outcomes[("raw", N)], f"{name} and the raw loop disagree on outcomes"
    best = {key: min(v) for key, v in walls.items()}
    best_cpu = {key: min(v) for key, v in cpus.items()}
    cpu_split = {name: _split(best_cpu[(name, M)], best_cpu[(name, N)]) for name in runs}
    inner = {name: sum(episode_s[(name, i)] for i in range(N)) / N for name in runs}
    split = {name: _split(best[(name, M)], best[(name, N)]) for name in runs}
    (raw_ep, raw_fixed), (h1_ep, h1_fixed), (h2_ep, h2_fixed) = split["raw"], split["harness_w1"], split["harness_w2"]
    _report("harness_vs_raw", {
        "episodes": [M, N], "horizon": HORIZON, "chunk": CHUNK, "reps": REPS, "cameras": "2 x 224x224",
        "successes": sum(r["success"] for r in outcomes[("raw", N)]),
        "raw_per_episode_s": round(raw_ep, 3), "harness_per_episode_s": round(h1_ep, 3),
        "per_episode_ratio": round(h1_ep / raw_ep, 3),
        "raw_episode_inside_s": round(inner["raw"], 3), "harness_episode_inside_s": round(inner["harness_w1"], 3),
        "inside_ratio": round(inner["harness_w1"] / inner["raw"], 3),
        "raw_fixed_s": round(raw_fixed, 2), "harness_fixed_s": round(h1_fixed, 2),
        "workers2_per_episode_s": round(h2_ep, 3), "workers2_fixed_s": round(h2_fixed, 2),
        "throughput_workers2_over_workers1": round(h1_ep / h2_ep, 3),
        "cpu_raw_per_episode_s": round(cpu_split["raw"][0], 3),
        "cpu_harness_per_episode_s": round(cpu_split["harness_w1"][0], 3),
        "cpu_per_episode_ratio": round(cpu_split["harness_w1"][0] / cpu_split["raw"][0], 3),
        "cpu_raw_fixed_s": round(cpu_split["raw"][1], 2), "cpu_harness_fixed_s": round(cpu_split["harness_w1"][1], 2),
        "best_walls_s": {f"{name}@{n}": round(w, 2) for (name, n), w in sorted(best.items())},
        "best_cpu_s": {f"{name}@{n}": round(c, 2) for (name, n), c in sorted(best_cpu.items())},
        "cpus": os.cpu_count(),
    })
