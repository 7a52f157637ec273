"""Episodes/min of MetaWorld in ``molmo-eval`` against ``lerobot-eval --env.type=metaworld`` on the same episodes.

Both sides play the same episodes with the same policy: a tiny ACT at random init with MetaWorld's features
(``tests/suites/tiny_policies.py``, 480² as the env renders), which never succeeds, so every episode runs LeRobot's
500 steps (``lerobot-eval``'s MetaWorld step limit is its env's, not ``--env.episode_length``). Theirs is
``lerobot-eval`` with its defaults (a video of each of the first 10 episodes, drawn by a second render per step)
at ``--eval.batch_size=1`` and ``=2``; ours ``molmo-eval policy=lerobot policy.mode=chunk benchmark=metaworld_<task>
workers=2``: the same actions (ACT's chunk runs open loop), MetaWorld drawing only the frames the policy reads (one
step in ``n_action_steps``). One run each, in fresh processes; wall time includes start-up. Report, not assert; rows
go to ``runs/perf.jsonl``. ``MOLMO_PERF_METAWORLD_TASK`` (default ``reach-v3``), ``MOLMO_PERF_METAWORLD_EPISODES``
(default 2), ``MOLMO_PERF_METAWORLD_WORKERS`` (default 2).
"""

from __future__ import annotations

import json
import os
import sys

import pytest
from perf_rows import append_rows, eval_run, timed
from tiny_policies import save_act  # tests/suites (tests/conftest.py puts it on sys.path)

from molmo_lerobot.suites import metaworld


@pytest.mark.perf
@pytest.mark.timeout(6 * 3600)
def test_metaworld_episodes_per_min_against_lerobot_eval(tmp_path):
    pytest.importorskip("metaworld")
    task = os.environ.get("MOLMO_PERF_METAWORLD_TASK", "reach-v3")
    n = int(os.environ.get("MOLMO_PERF_METAWORLD_EPISODES", "2"))
    workers = int(os.environ.get("MOLMO_PERF_METAWORLD_WORKERS", "2"))
    act = save_act(tmp_path / "act", "metaworld", metaworld.IMAGE_SIZE)
    env = {**os.environ, "MUJOCO_GL": "egl", "HF_HUB_OFFLINE": "1"}

    table = []
    for batch in (1, 2):
        out = tmp_path / f"theirs_{batch}"
        wall, cpu, _ = timed(
            [sys.executable, "-m", "lerobot.scripts.lerobot_eval", f"--policy.path={act}", "--policy.device=cpu",
             "--env.type=metaworld", f"--env.task={task}", f"--eval.n_episodes={n}", f"--eval.batch_size={batch}",
             "--seed=0", f"--output_dir={out}"], env)
        info = json.loads((out / "eval_info.json").read_text())["overall"]
        assert info["n_episodes"] == n
        table.append({"side": f"lerobot-eval batch_size={batch}", "policy": "tiny ACT", "episodes": n,
                      "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "eps_per_min": round(60 * n / wall, 3),
                      "eps_per_min_excl_startup": round(60 * n / info["eval_s"], 3),
                      "successes": round(info["pc_success"] * n / 100)})
    wall, cpu, rows = eval_run(["policy=lerobot", f"policy.path={act}", "policy.device=cpu", "policy.mode=chunk",
                                f"benchmark=metaworld_{task}", f"benchmark.episodes_per_task={n}",
                                f"workers={workers}"], tmp_path / "ours", env)
    assert len(rows) == n  # the same episodes as theirs
    busy = sum(r["duration_s"] for r in rows) / min(workers, n)
    table.append({"side": f"molmo-eval workers={workers}", "policy": "tiny ACT", "episodes": n,
                  "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "eps_per_min": round(60 * n / wall, 3),
                  "eps_per_min_excl_startup": round(60 * n / busy, 3),
                  "successes": sum(bool(r["success"]) for r in rows), "steps": sum(int(r["steps"]) for r in rows)})
    append_rows(f"metaworld_{task}", table, test="metaworld_throughput",
                ratio_wall=round(table[0]["wall_s"] / table[-1]["wall_s"], 3))
    print(f"\nMetaWorld {task}: {n} episodes, 480² frames")
    for row in table:
        print("  " + "  ".join(f"{k}={v}" for k, v in row.items()))
    for row in table[:2]:
        print(f"  episodes/min molmo-eval / {row['side']}: x{row['wall_s'] / table[-1]['wall_s']:.2f} (wall), "
              f"x{table[-1]['eps_per_min_excl_startup'] / row['eps_per_min_excl_startup']:.2f} (excluding start-up)")
