"""door_v1 through the other two ways in: the Gymnasium env (the base steps like any group) and
``policy=remote`` (the same outcomes as the policy in process). Slow: the recorded molmo-eval path is
in the default run (test_door_v1.py)."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.config import compose
from molmo_lerobot.runner.evaluate import run_evaluation


@pytest.mark.slow
def test_gym_env_drives_the_mobile_base_in_a_door_room():
    import gymnasium as gym

    import molmo_lerobot.gym_env  # noqa: F401  (registers molmo_lerobot/<benchmark>)

    env = gym.make("molmo_lerobot/door_v1", horizon=10)
    try:
        obs, _ = env.reset(seed=0)
        assert env.action_space.shape == (11,) and obs["agent_pos"].shape == (11,)
        assert set(obs["pixels"]) == {"head_camera", "wrist_camera"}
        action = obs["agent_pos"].copy()
        action[1] += 0.05  # 5 cm along y, the rest held
        for _ in range(10):
            obs, _, _, truncated, _ = env.step(action)
        assert truncated and obs["agent_pos"][1] == pytest.approx(action[1], abs=2e-3)
        assert obs["agent_pos"][0] == pytest.approx(action[0], abs=2e-3)
    finally:
        env.close()


@pytest.mark.slow
def test_remote_random_gives_the_in_process_door_outcomes(tmp_path):
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.serving.server import build_server, serve_in_thread

    def run(*over):
        return run_evaluation(compose(["benchmark=door_v1", "limit=2", "horizon=40", "seed=3", "progress=false",
                                       f"output_dir={tmp_path / over[0].split('=')[1]}", *over]))

    local = run("policy=random", "workers=1")
    with serve_in_thread(build_server(Plugins(), {"name": "random"}, port=0)) as srv:
        served = run("policy=remote", f"policy.port={srv.port}", "workers=1")
    key = [(e.episode_index, e.success, e.steps, e.seed, e.error) for e in local.episodes]
    assert served.summary["n_errors"] == 0 and key == [(e.episode_index, e.success, e.steps, e.seed, e.error)
                                                      for e in served.episodes]
