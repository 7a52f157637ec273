"""Episodes/min of LIBERO in ``molmo-eval`` against ``lerobot-eval --env.type=libero`` on the same episodes.

Both sides play the same episodes with the same policy: a tiny ACT at random init with LeRobot's LIBERO
features (``tests/suites/libero_act.py``), loaded by ``--policy.path=`` and ``policy.path=``. Theirs is
``lerobot-eval`` in the LIBERO venv with its defaults (hard reset, a video per episode, 360² cameras, the suite's
step limit); ours ``molmo-eval policy=lerobot benchmark=libero_object benchmark.episodes_per_task=E workers=2``.
One run each, one after the other, in fresh processes; wall time includes start-up, and "excluding start-up"
is their ``eval_s`` (their rollout loop, env construction included) and our episodes' summed durations over the
workers (resets and steps; not the worker's LIBERO process start). Report, not assert; rows go to
``runs/perf.jsonl``. ``MOLMO_PERF_LIBERO_TASKS`` (default 2) tasks of ``libero_object`` × ``MOLMO_PERF_LIBERO_EPISODES``
(default 2) init states each; ``MOLMO_PERF_LIBERO_WORKERS`` (default 2) our workers.
"""

from __future__ import annotations

import json
import os

import pytest
from libero_act import save_libero_act  # tests/suites (tests/conftest.py puts it on sys.path)
from perf_rows import append_rows, eval_run, timed

from molmo_lerobot.suites.libero import libero_venv

SUITE = "libero_object"
SIZE = 360  # lerobot-eval's LIBERO default


@pytest.mark.perf
def test_libero_episodes_per_min_against_lerobot_eval(tmp_path):
    venv = libero_venv()
    if not (venv / "bin" / "python").exists():
        pytest.skip(f"no LIBERO venv at {venv} (make .libero-venv)")
    tasks = int(os.environ.get("MOLMO_PERF_LIBERO_TASKS", "2"))
    per_task = int(os.environ.get("MOLMO_PERF_LIBERO_EPISODES", "2"))
    workers = int(os.environ.get("MOLMO_PERF_LIBERO_WORKERS", "2"))
    act = save_libero_act(tmp_path / "act", SIZE)
    env = {**os.environ, "MUJOCO_GL": "egl", "HF_HUB_OFFLINE": "1", "LIBERO_CONFIG_PATH": str(venv / "libero-config")}

    theirs_wall, theirs_cpu, _ = timed(
        [str(venv / "bin" / "python"), "-m", "lerobot.scripts.lerobot_eval", f"--policy.path={act}",
         "--policy.device=cpu", "--env.type=libero", f"--env.task={SUITE}",
         f"--env.task_ids=[{','.join(map(str, range(tasks)))}]", f"--eval.n_episodes={per_task}",
         "--eval.batch_size=1", "--seed=0", f"--output_dir={tmp_path / 'theirs'}"], env)
    info = json.loads((tmp_path / "theirs" / "eval_info.json").read_text())["overall"]
    ours_wall, ours_cpu, rows = eval_run(
        ["policy=lerobot", f"policy.path={act}", "policy.device=cpu", f"benchmark={SUITE}",
         f"benchmark.episodes_per_task={per_task}", f"limit={tasks * per_task}", f"workers={workers}"],
        tmp_path / "ours", env)

    n = tasks * per_task
    assert info["n_episodes"] == len(rows) == n  # the same episodes on both sides
    busy = sum(r["duration_s"] for r in rows) / min(workers, n)  # the episodes' time, workers in parallel
    table = [
        {"side": "lerobot-eval", "episodes": n, "wall_s": round(theirs_wall, 1), "cpu_s": round(theirs_cpu, 1),
         "eps_per_min": round(60 * n / theirs_wall, 3), "eps_per_min_excl_startup": round(60 * n / info["eval_s"], 3),
         "successes": round(info["pc_success"] * n / 100)},
        {"side": f"molmo-eval workers={workers}", "episodes": n, "wall_s": round(ours_wall, 1),
         "cpu_s": round(ours_cpu, 1), "eps_per_min": round(60 * n / ours_wall, 3),
         "eps_per_min_excl_startup": round(60 * n / busy, 3), "successes": sum(bool(r["success"]) for r in rows)},
    ]
    ratio = theirs_wall / ours_wall
    append_rows(SUITE, table, test="libero_throughput", ratio_wall=round(ratio, 3))
    print(f"\nLIBERO {SUITE}: {tasks} tasks x {per_task} init states, {SIZE}² cameras, tiny ACT")
    for row in table:
        print("  " + "  ".join(f"{k}={v}" for k, v in row.items()))
    print(f"  episodes/min ours / lerobot-eval: x{ratio:.2f} (wall), "
          f"x{table[1]['eps_per_min_excl_startup'] / table[0]['eps_per_min_excl_startup']:.2f} (excluding start-up)")
