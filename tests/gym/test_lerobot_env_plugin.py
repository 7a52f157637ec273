"""The lerobot_env_molmo distribution: LeRobot finds it, its features match our datasets, and
lerobot-eval scores the same episodes as molmo-eval (slow)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytest.importorskip("lerobot_env_molmo", reason="make .venv installs plugins/lerobot_env_molmo")

from lerobot.envs.configs import EnvConfig

from molmo_lerobot.config import compose
from molmo_lerobot.runner.evaluate import run_evaluation


def test_lerobot_imports_the_plugin_and_names_features_as_our_datasets():
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    assert "molmo" in EnvConfig.get_known_choices()
    cfg = EnvConfig.get_choice_class("molmo")(task="pick_v1", horizon=5)
    assert cfg.features_map == {"action": "action", "agent_pos": "observation.state",
                                "pixels/exterior": "observation.images.exterior",
                                "pixels/wrist": "observation.images.wrist"}
    assert cfg.features["pixels/wrist"].shape == (224, 224, 3) and cfg.features["action"].shape == (8,)
    vec = cfg.create_envs(n_envs=2)["molmo"][0]
    try:
        _, info = vec.reset(seed=[0, 1])
        assert list(info["episode_index"]) == [0, 1]
        assert list(vec.call("task_description")) == list(info["task_description"])
        assert vec.call("_max_episode_steps") == (5, 5)
    finally:
        vec.close()


def test_environment_state_reaches_a_lerobot_policy_as_observation_environment_state():
    from lerobot.envs.utils import preprocess_observation

    cfg = EnvConfig.get_choice_class("molmo")(task="pick_v1", horizon=5, environment_state=True)
    assert cfg.features_map["environment_state"] == "observation.environment_state"
    assert cfg.features["environment_state"].shape == (13,)
    vec = cfg.create_envs(n_envs=1)["molmo"][0]
    try:
        obs, _ = vec.reset(seed=[0])
        batch = preprocess_observation(obs)
    finally:
        vec.close()
    assert tuple(batch["observation.environment_state"].shape) == (1, 13)
    assert tuple(batch["observation.state"].shape) == (1, cfg.features["agent_pos"].shape[0])


@pytest.mark.slow
def test_lerobot_eval_matches_molmo_eval_per_episode(tmp_path):
    """ACT trained for 2 steps on a record=true run: lerobot-eval (any-step success, LeRobot's
    pc_success) and molmo-eval's success_once agree episode by episode, and so do both eval_info.json
    files' per-episode rewards and averages."""
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl"}
    rec = tmp_path / "rec"
    run_evaluation(compose(["policy=scripted", "benchmark=pick_v1", "workers=2", "limit=4", "horizon=30",
                            "record=true", "progress=false", f"output_dir={rec}"]))
    train = tmp_path / "train"
    subprocess.run([sys.executable, "-m", "lerobot.scripts.lerobot_train", "--dataset.repo_id=local/pick_v1-scripted",
                    f"--dataset.root={rec / 'dataset'}", "--dataset.video_backend=pyav", "--policy.type=act",
                    "--policy.device=cpu", "--policy.push_to_hub=false", "--policy.pretrained_backbone_weights=null",
                    "--steps=2", "--batch_size=2", "--num_workers=0", "--save_freq=2", "--wandb.enable=false",
                    f"--output_dir={train}"], env=env, check=True, capture_output=True, timeout=900)
    ckpt = train / "checkpoints" / "000002" / "pretrained_model"
    proc = subprocess.run([sys.executable, "-m", "lerobot.scripts.lerobot_eval", f"--policy.path={ckpt}",
                           "--env.type=molmo", "--env.task=pick_v1", "--env.horizon=30", "--eval.n_episodes=4",
                           "--eval.batch_size=2", "--policy.device=cpu", "--seed=0",
                           f"--output_dir={tmp_path / 'leval'}"], env=env, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    info = json.loads((tmp_path / "leval" / "eval_info.json").read_text())
    (task,) = info["per_task"]
    theirs = task["metrics"]["successes"]
    ours = run_evaluation(compose(["policy=lerobot", f"policy.path={ckpt}", "policy.device=cpu", "benchmark=pick_v1",
                                   "workers=1", "limit=4", "horizon=30", "progress=false",
                                   f"output_dir={tmp_path / 'molmo'}"]))
    assert ours.summary["n_errors"] == 0
    assert theirs == [e.success_once for e in ours.episodes]
    assert info["overall"]["n_episodes"] == 4
    # molmo-eval's eval_info.json: the same per-episode rewards and successes, the same averages
    mine = json.loads((tmp_path / "molmo" / "eval_info.json").read_text())
    (row,) = mine["per_task"]
    assert row["metrics"]["successes"] == theirs
    for key in ("sum_rewards", "max_rewards"):
        assert row["metrics"][key] == pytest.approx(task["metrics"][key], rel=0, abs=1e-9), key
    for key in ("pc_success", "avg_sum_reward", "avg_max_reward", "n_episodes"):
        assert mine["overall"][key] == pytest.approx(info["overall"][key], rel=0, abs=1e-9), key
