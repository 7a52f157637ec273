"""Episodes/min of LIBERO in ``molmo-eval`` against ``lerobot-eval --env.type=libero`` on the same episodes.

Both sides play the same episodes with the same policy: a tiny ACT at random init with LeRobot's LIBERO
features (``tests/suites/tiny_policies.py``), loaded by ``--policy.path=`` and ``policy.path=``. Theirs is
``lerobot-eval`` in the LIBERO venv with its defaults (hard reset, a video per episode, 360² cameras, the suite's
step limit, ``select_action`` at every step); ours ``molmo-eval policy=lerobot policy.mode=chunk benchmark=libero_object
benchmark.episodes_per_task=E workers=2``: the same actions (ACT's ``select_action`` plays out the chunk it
predicts; the chunk runs open loop here), and LIBERO draws only the frames the policy reads, one step in
``n_action_steps``. A third row is ``molmo-eval policy=random`` on the same episodes, which draws no frame after
a reset (``lerobot-eval`` has no random policy; its nearest is the random-init ACT row).
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
from perf_rows import append_rows, eval_run, timed
from tiny_policies import save_act  # tests/suites (tests/conftest.py puts it on sys.path)

from molmo_lerobot.suites.libero import libero_venv

SUITE = "libero_object"
SIZE = 360  # lerobot-eval's LIBERO default


@pytest.mark.perf
@pytest.mark.timeout(6 * 3600)  # 50 episodes a side: ~1.5 hours of this 2-core machine
def test_libero_episodes_per_min_against_lerobot_eval(tmp_path):
    venv = libero_venv()
    if not (venv / "bin" / "python").exists():
        pytest.skip(f"no LIBERO venv at {venv} (make .libero-venv)")
    tasks = int(os.environ.get("MOLMO_PERF_LIBERO_TASKS", "2"))
    per_task = int(os.environ.get("MOLMO_PERF_LIBERO_EPISODES", "2"))
    workers = int(os.environ.get("MOLMO_PERF_LIBERO_WORKERS", "2"))
    act = save_act(tmp_path / "act", "libero", SIZE)
    env = {**os.environ, "MUJOCO_GL": "egl", "HF_HUB_OFFLINE": "1", "LIBERO_CONFIG_PATH": str(venv / "libero-config")}

    theirs_wall, theirs_cpu, _ = timed(
        [str(venv / "bin" / "python"), "-m", "lerobot.scripts.lerobot_eval", f"--policy.path={act}",
         "--policy.device=cpu", "--env.type=libero", f"--env.task={SUITE}",
         f"--env.task_ids=[{','.join(map(str, range(tasks)))}]", f"--eval.n_episodes={per_task}",
         "--eval.batch_size=1", "--seed=0", f"--output_dir={tmp_path / 'theirs'}"], env)
    info = json.loads((tmp_path / "theirs" / "eval_info.json").read_text())["overall"]
    ours = {}
    for name, policy in (("act", ["policy=lerobot", f"policy.path={act}", "policy.device=cpu", "policy.mode=chunk"]),
                         ("random", ["policy=random"])):
        ours[name] = eval_run([*policy, f"benchmark={SUITE}", f"benchmark.episodes_per_task={per_task}",
                               f"limit={tasks * per_task}", f"workers={workers}"], tmp_path / f"ours_{name}", env)

    n = tasks * per_task
    table = [
        {"side": "lerobot-eval", "policy": "tiny ACT", "episodes": n, "wall_s": round(theirs_wall, 1),
         "cpu_s": round(theirs_cpu, 1), "eps_per_min": round(60 * n / theirs_wall, 3),
         "eps_per_min_excl_startup": round(60 * n / info["eval_s"], 3),
         "successes": round(info["pc_success"] * n / 100)},
    ]
    for name, (wall, cpu, rows) in ours.items():
        assert info["n_episodes"] == len(rows) == n  # the same episodes on both sides
        busy = sum(r["duration_s"] for r in rows) / min(workers, n)  # the episodes' time, workers in parallel
        table.append({"side": f"molmo-eval workers={workers}", "policy": {"act": "tiny ACT", "random": "random"}[name],
                      "episodes": n, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
                      "eps_per_min": round(60 * n / wall, 3), "eps_per_min_excl_startup": round(60 * n / busy, 3),
                      "successes": sum(bool(r["success"]) for r in rows),
                      "steps": sum(int(r["steps"]) for r in rows)})
    ratio = theirs_wall / table[1]["wall_s"]
    append_rows(SUITE, table, test="libero_throughput", ratio_wall=round(ratio, 3))
    print(f"\nLIBERO {SUITE}: {tasks} tasks x {per_task} init states, {SIZE}² cameras")
    for row in table:
        print("  " + "  ".join(f"{k}={v}" for k, v in row.items()))
    for row in table[1:]:
        print(f"  episodes/min ours ({row['policy']}) / lerobot-eval (tiny ACT): x{theirs_wall / row['wall_s']:.2f} "
              f"(wall), x{row['eps_per_min_excl_startup'] / table[0]['eps_per_min_excl_startup']:.2f} "
              "(excluding start-up)")
