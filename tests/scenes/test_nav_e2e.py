"""nav_v1 end to end: molmo-eval with the expert, recorded as a LeRobot dataset whose features carry the
base group (default run); the Gymnasium env, policy=remote, the scores and the generator (slow)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from molmo_lerobot.config import compose
from molmo_lerobot.paths import data_path
from molmo_lerobot.runner.evaluate import run_evaluation

BASE = ["base_x", "base_y", "base_theta"]


@pytest.mark.slow  # the default run keeps it under 10 minutes; make test-all runs it
def test_a_recorded_nav_episode_loads_in_lerobot_with_the_base_group(tmp_path, fork_servers):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    out = tmp_path / "run"
    res = run_evaluation(compose(["policy=scripted", "benchmark=nav_v1", "workers=1", "limit=1", "horizon=100",
                                  "record=true", "progress=false", f"output_dir={out}"]), fork_servers)
    (episode,) = res.episodes
    assert episode.error is None and episode.success and episode.steps == 100
    ds = LeRobotDataset("local/nav_v1-scripted", root=out / "dataset", video_backend="pyav")
    assert ds.features["action"]["names"][:3] == BASE and ds.features["action"]["shape"] == (11,)
    assert ds.features["observation.state"]["names"][:3] == BASE
    assert set(ds.meta.video_keys) == {"observation.images.head_camera", "observation.images.wrist_camera"}
    first, last = ds[0], ds[len(ds) - 1]
    spec = json.loads((data_path("benchmarks") / "nav_v1" / "benchmark.json").read_text())[0]
    assert np.allclose(first["observation.state"][:2].numpy(), spec["task"]["robot_base_pose"][:2], atol=1e-4)
    assert np.linalg.norm((last["observation.state"][:2] - first["observation.state"][:2]).numpy()) > 2.0  # it drove
    assert bool(last["next.success"]) and json.loads((out / "dataset" / "meta" / "info.json").read_text())[
        "robot_type"] == "mobile_franka"


@pytest.mark.slow
def test_gym_env_steps_the_base_like_any_group():
    import gymnasium as gym

    import molmo_lerobot.gym_env  # noqa: F401  (registers molmo_lerobot/<benchmark>)

    env = gym.make("molmo_lerobot/nav_v1", horizon=10)
    try:
        obs, _ = env.reset(seed=0)
        assert env.action_space.shape == (11,) and obs["agent_pos"].shape == (11,)
        assert set(obs["pixels"]) == {"head_camera", "wrist_camera"}
        action = obs["agent_pos"].copy()
        action[0] += 0.05  # 5 cm along x, the rest held
        for _ in range(10):
            obs, _, _, truncated, _ = env.step(action)
        assert truncated and obs["agent_pos"][0] == pytest.approx(action[0], abs=2e-3)
        assert obs["agent_pos"][1] == pytest.approx(action[1], abs=2e-3)
    finally:
        env.close()


@pytest.mark.slow
def test_remote_random_gives_the_in_process_outcomes(tmp_path):
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.serving.server import build_server, serve_in_thread

    def run(*over):
        return run_evaluation(compose(["benchmark=nav_v1", "limit=2", "horizon=40", "seed=3", "progress=false",
                                       f"output_dir={tmp_path / over[0].split('=')[1]}", *over]))

    local = run("policy=random", "workers=1")
    with serve_in_thread(build_server(Plugins(), {"name": "random"}, port=0)) as srv:
        served = run("policy=remote", f"policy.port={srv.port}", "workers=1")
    key = [(e.episode_index, e.success, e.steps, e.seed, e.error) for e in local.episodes]
    assert served.summary["n_errors"] == 0 and key == [(e.episode_index, e.success, e.steps, e.seed, e.error)
                                                      for e in served.episodes]


@pytest.mark.slow
def test_generator_reproduces_nav_v1():
    from molmo_lerobot.content.libero.generate_nav import generate_benchmark

    episodes, meta = generate_benchmark(12, 5, 0, "nav_v1")
    root = data_path("benchmarks") / "nav_v1"
    assert episodes == json.loads((root / "benchmark.json").read_text())
    assert meta == json.loads((root / "benchmark_metadata.json").read_text())
