"""Episodes/min of ALOHA in ``molmo-eval`` against ``lerobot-eval --env.type=aloha`` on the same episodes.

Both sides play the same episodes of AlohaInsertion-v0 with the same policy: a tiny ACT at random init with ALOHA's
features (``tests/suites/tiny_policies.py``, 480 × 640 top camera), loaded by ``--policy.path=`` and
``policy.path=``. Theirs is ``lerobot-eval`` in the ALOHA venv with its defaults (gym-aloha draws its three 480 × 640
cameras at every step, a video per episode), with ``--eval.batch_size=1`` and ``=2`` (the latter with
``--eval.use_async_envs=false``: LeRobot 0.6.1's default async envs start their env processes with ``forkserver``,
which never import ``gym_aloha``, so ``gym.make`` there fails with "Namespace gym_aloha not found"); ours ``molmo-eval
policy=lerobot policy.mode=chunk benchmark=aloha_insertion workers=2``: the same actions (ACT's ``select_action``
plays out the chunk it predicts; the chunk runs open loop here), and the server draws only the top camera, only at
the steps whose frame the policy reads (one in ``n_action_steps``). A last row is ``molmo-eval policy=random`` on the
same episodes (no frame read). One run each, in fresh processes; wall time includes start-up; "excluding start-up"
is their ``eval_s`` and our episodes' summed durations over the workers. Report, not assert; rows go to
``runs/perf.jsonl``. ``MOLMO_PERF_ALOHA_EPISODES`` (default 2) episodes of ``MOLMO_PERF_ALOHA_STEPS`` (default 400,
LeRobot's ``episode_length``) steps.
"""

from __future__ import annotations

import json
import os

import pytest
from perf_rows import append_rows, eval_run, timed
from tiny_policies import save_act  # tests/suites (tests/conftest.py puts it on sys.path)

from molmo_lerobot.suites import aloha

TASK, BENCHMARK = "AlohaInsertion-v0", "aloha_insertion"
WORKERS = 2


@pytest.mark.perf
@pytest.mark.timeout(6 * 3600)
def test_aloha_episodes_per_min_against_lerobot_eval(tmp_path):
    venv = aloha.aloha_venv()
    if not (venv / "bin" / "python").exists():
        pytest.skip(f"no ALOHA venv at {venv} (make .aloha-venv)")
    n = int(os.environ.get("MOLMO_PERF_ALOHA_EPISODES", "2"))
    steps = int(os.environ.get("MOLMO_PERF_ALOHA_STEPS", str(aloha.MAX_STEPS)))
    act = save_act(tmp_path / "act", "aloha", (aloha.IMAGE_HEIGHT, aloha.IMAGE_WIDTH))
    env = {**os.environ, "MUJOCO_GL": "egl", "HF_HUB_OFFLINE": "1"}

    table = []
    for batch in (1, 2):
        out = tmp_path / f"theirs_{batch}"
        wall, cpu, _ = timed(
            [str(venv / "bin" / "python"), "-m", "lerobot.scripts.lerobot_eval", f"--policy.path={act}",
             "--policy.device=cpu", "--env.type=aloha", f"--env.task={TASK}", f"--env.episode_length={steps}",
             f"--eval.n_episodes={n}", f"--eval.batch_size={batch}", "--eval.use_async_envs=false", "--seed=0",
             f"--output_dir={out}"], env)
        info = json.loads((out / "eval_info.json").read_text())["overall"]
        assert info["n_episodes"] == n
        table.append({"side": f"lerobot-eval batch_size={batch}", "policy": "tiny ACT", "episodes": n,
                      "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "eps_per_min": round(60 * n / wall, 3),
                      "eps_per_min_excl_startup": round(60 * n / info["eval_s"], 3),
                      "successes": round(info["pc_success"] * n / 100)})
    lerobot = ["policy=lerobot", f"policy.path={act}", "policy.device=cpu", "policy.mode=chunk"]
    for name, policy in (("tiny ACT", lerobot), ("random", ["policy=random"])):
        wall, cpu, rows = eval_run([*policy, f"benchmark={BENCHMARK}", f"benchmark.episodes_per_task={n}",
                                    f"horizon={steps}", f"workers={WORKERS}"], tmp_path / f"ours_{len(table)}", env)
        assert len(rows) == n  # the same episodes as theirs
        busy = sum(r["duration_s"] for r in rows) / min(WORKERS, n)
        table.append({"side": f"molmo-eval workers={WORKERS}", "policy": name, "episodes": n, "wall_s": round(wall, 1),
                      "cpu_s": round(cpu, 1), "eps_per_min": round(60 * n / wall, 3),
                      "eps_per_min_excl_startup": round(60 * n / busy, 3),
                      "successes": sum(bool(r["success"]) for r in rows),
                      "env_steps": sum(int(r["steps"]) for r in rows)})
    append_rows(BENCHMARK, table, test="aloha_throughput", steps=steps, ratio_wall=round(
        table[0]["wall_s"] / table[2]["wall_s"], 3))
    print(f"\nALOHA {TASK}: {n} episodes of {steps} steps")
    for row in table:
        print("  " + "  ".join(f"{k}={v}" for k, v in row.items()))
    for theirs in table[:2]:
        for ours in table[2:]:
            print(f"  episodes/min ours ({ours['policy']}) / {theirs['side']} (tiny ACT): "
                  f"x{theirs['wall_s'] / ours['wall_s']:.2f} (wall), "
                  f"x{ours['eps_per_min_excl_startup'] / theirs['eps_per_min_excl_startup']:.2f} (excluding start-up)")
