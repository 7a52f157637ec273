"""Spine timings, measured in one run (``make perf`` or ``pytest -m perf -s tests/perf``).

* harness / raw: ``run_evaluation`` with one worker process versus a bare in-process loop
  over the same episodes that does the same physics steps, renders and policy calls with
  plain ``mujoco`` calls (no plugins lookups, validation, recorders, result files,
  worker supervision). Target <= 1.05.
* workers=2 / workers=1 throughput on the same episodes. Target >= 1.8 on 2 cores.

Figures are printed (and appended to ``runs/perf.jsonl``); nothing is asserted about speed.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import mujoco
import numpy as np
import pytest

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.config import compose
from molmo_lerobot.paths import data_path
from molmo_lerobot.plugins import get_plugins
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.runner.evaluate import episode_seed, run_evaluation
from molmo_lerobot.runner.policy import make_policy
from molmo_lerobot.runner.rollout import resolve_horizon
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing

pytestmark = pytest.mark.perf
N_EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "20"))
POLICY = os.environ.get("MOLMO_PERF_POLICY", "scripted")


def _report(name: str, figures: dict) -> None:
    line = json.dumps({"benchmark": name, **figures})
    print("\n" + line)
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        f.write(line + "\n")


def raw_loop(n: int, policy_name: str) -> tuple[float, int, int, int]:
    """The same episodes as the harness, driven with bare mujoco calls in this process."""
    plugins = get_plugins()
    bench = load_benchmark(data_path("benchmarks") / "pick_v1")
    timing = Timing()
    policy = make_policy({"name": policy_name})
    steps = renders = calls = 0
    t0 = time.perf_counter()
    for i in range(n):
        spec = bench.episodes[i]
        seed = episode_seed(0, spec.model_dump(mode="json"))
        task_type = plugins.task_type(spec.task_name)
        horizon = resolve_horizon(None, spec.task, task_type.default_horizon_sec, timing.policy_dt_ms)
        env = build_env(spec, timing, plugins)
        env.reset(seed)
        task = task_type.create(spec, env)
        m, d = env.model, env.data
        renderer = mujoco.Renderer(m, height=spec.img_resolution[1], width=spec.img_resolution[0]) \
            if policy.needs_images else None
        policy.reset(EpisodeContext(spec=spec, episode_index=i, seed=seed, prompt=spec.language.task_description,
                                    move_groups=env.move_groups, policy_dt_s=timing.policy_dt_s, env=env))
        task.setup()
        queue: list[dict] = []
        for _ in range(horizon):
            if not queue:
                obs = env.observe(images=False)
                if policy.needs_images:
                    obs["images"] = {}
                    for cam in env.camera_names:
                        renderer.update_scene(d, camera=cam)
                        obs["images"][cam] = renderer.render()
                        renders += 1
                obs["prompt"] = spec.language.task_description
                out = policy.act(obs)
                calls += 1
                arm, grip = np.atleast_2d(out["arm"]), np.atleast_2d(out["gripper"])
                queue = [{"arm": arm[t], "gripper": grip[t]} for t in range(len(arm))]
            action = queue.pop(0)
            start = d.ctrl.copy()
            for g, goal in action.items():
                env.robot.command(d, g, goal)
            delta = d.ctrl - start
            for k in range(1, timing.ctrl_ticks + 1):
                d.ctrl[:] = start + delta * (k / timing.ctrl_ticks)
                mujoco.mj_step(m, d, nstep=timing.substeps)
            task.success()
            steps += 1
        if renderer is not None:
            renderer.close()
    return time.perf_counter() - t0, steps, renders, calls


def harness(n: int, workers: int, policy_name: str, out: Path) -> float:
    cfg = compose([f"policy={policy_name}", f"workers={workers}", f"limit={n}", f"output_dir={out}", "progress=false"])
    t0 = time.perf_counter()
    res = run_evaluation(cfg)
    elapsed = time.perf_counter() - t0
    assert res.summary["n_episodes"] == n and res.summary["n_errors"] == 0
    return elapsed


def test_harness_vs_raw_loop(tmp_path):
    raw_s, steps, renders, calls = raw_loop(N_EPISODES, POLICY)
    harness_s = harness(N_EPISODES, 1, POLICY, tmp_path / "w1")
    _report("harness_vs_raw", {"policy": POLICY, "episodes": N_EPISODES, "raw_s": round(raw_s, 2),
                               "harness_s": round(harness_s, 2), "ratio": round(harness_s / raw_s, 3),
                               "steps": steps, "renders": renders, "policy_calls": calls})


def test_workers_scaling(tmp_path):
    one = harness(N_EPISODES, 1, POLICY, tmp_path / "w1")
    two = harness(N_EPISODES, 2, POLICY, tmp_path / "w2")
    a = [json.loads(x) for x in (tmp_path / "w1" / "episodes.jsonl").read_text().splitlines()]
    b = [json.loads(x) for x in (tmp_path / "w2" / "episodes.jsonl").read_text().splitlines()]
    assert [(r["episode_index"], r["success"], r["success_once"]) for r in a] == \
        [(r["episode_index"], r["success"], r["success_once"]) for r in b]
    _report("workers_scaling", {"policy": POLICY, "episodes": N_EPISODES, "workers1_s": round(one, 2),
                                "workers2_s": round(two, 2), "throughput_ratio": round(one / two, 3)})
