"""The Gymnasium env: LeRobot's conventions, clear errors, and the same trial as molmo-eval."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import molmo_lerobot.gym_env  # noqa: F401  (registers molmo_lerobot/<benchmark>)
from molmo_lerobot.config import compose
from molmo_lerobot.gym_env import EpisodeIndexError, MolmoEnv
from molmo_lerobot.runner.episode import EpisodeSetupError
from molmo_lerobot.runner.evaluate import run_evaluation


@pytest.fixture(scope="module")
def env():
    e = gym.make("molmo_lerobot/pick_v1", horizon=12)
    yield e
    e.close()


def test_check_env_passes(env):
    from gymnasium.utils.env_checker import check_env

    check_env(env.unwrapped, skip_render_check=False)


def test_spaces_and_info_follow_lerobot_conventions(env):
    obs, info = env.reset(seed=61)  # 61 mod 60: episode 1
    assert info["episode_index"] == 1 and info["task"] == "pick" and info["task_description"]
    assert set(obs) == {"pixels", "agent_pos"} and set(obs["pixels"]) == {"exterior", "wrist"}
    assert obs["pixels"]["exterior"].dtype == np.uint8 and obs["pixels"]["exterior"].shape == (224, 224, 3)
    assert obs["agent_pos"].shape == (8,) == env.action_space.shape
    _, info = env.reset()  # no seed: the next episode in order
    assert info["episode_index"] == 2
    hold = obs["agent_pos"]
    for t in range(12):
        obs, _reward, terminated, truncated, info = env.step(hold)
        assert truncated == (t == 11) and not terminated and {"is_success", "success_once"} <= set(info)
    assert env.render().shape == (224, 224, 3)
    assert env.unwrapped.task_description() == info["task_description"]


def test_bad_input_is_one_clear_error(env):
    with pytest.raises(EpisodeSetupError, match=r"unknown benchmark 'nope'.*pick_v1"):
        MolmoEnv("nope")
    with pytest.raises(EpisodeIndexError, match=r"episode_index 60 is outside benchmark 'pick_v1'.*0..59"):
        MolmoEnv("pick_v1", episode_index=60)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action has shape \(7,\), expected \(8,\): arm \(7\) \+ gripper \(1\)"):
        env.step(np.zeros(7, np.float32))


def test_eval_options_are_validated_as_molmo_eval_validates_its_config():
    """The env's run config goes through RunConfig, as molmo-eval's does (it used to be taken unchecked)."""
    from molmo_lerobot.run_config import RunConfigError

    with pytest.raises(RunConfigError) as err:
        MolmoEnv("pick_v1", eval_options={"horizons": {"pick": -5}, "camera": {"rand_level": 200}},
                 timing={"policy_dt_ms": 0})
    assert any(line.startswith("horizons.pick: expected a positive number of seconds") for line in err.value.problems)
    assert any(line.startswith("timing.policy_dt_ms: expected a positive number") for line in err.value.problems)
    assert len(err.value.problems) == 3


def test_replayed_actions_give_molmo_evals_trial(tmp_path, fork_servers):
    """The same actions through the Gymnasium env and through molmo-eval (policy=replay): the same
    robot state at every step (from the recorded dataset) and the same outcome."""
    import pandas as pd

    steps, index = 20, 3
    genv = MolmoEnv("pick_v1", episode_index=index, horizon=steps)
    obs, info = genv.reset()
    rng = np.random.default_rng(0)
    actions = obs["agent_pos"] + rng.uniform(-0.05, 0.05, (steps, 8))
    actions[:, 7] = rng.uniform(0, 1, steps)
    actions = actions.astype(np.float32)  # what both sides step with, bit for bit
    states = [obs["agent_pos"]]
    for a in actions:
        obs, _, _, truncated, info = genv.step(a)
        states.append(obs["agent_pos"])
    genv.close()
    assert truncated
    np.save(tmp_path / "actions.npy", actions)

    out = tmp_path / "run"
    res = run_evaluation(compose(["policy=replay", f"policy.actions={tmp_path / 'actions.npy'}", "benchmark=pick_v1",
                                  "workers=1", f"episodes=[{index}]", f"horizon={steps}", "record=true",
                                  "progress=false", f"output_dir={out}"]), fork_servers)
    ep = next(e for e in res.episodes if e.episode_index == index)
    assert ep.error is None and ep.seed == info["seed"]
    assert (ep.success, ep.success_once) == (info["is_success"], info["success_once"])
    eval_records = out / "dataset" / "meta" / "eval" / "episodes.jsonl"
    records = [json.loads(line) for line in eval_records.read_text().splitlines()]
    ds_index = next(r["episode_index"] for r in records if r["benchmark_episode_index"] == index)
    frames = pd.concat(pd.read_parquet(p) for p in sorted((out / "dataset" / "data").rglob("*.parquet")))
    recorded = np.stack(frames[frames["episode_index"] == ds_index]["observation.state"].to_numpy())
    np.testing.assert_array_equal(recorded, np.stack(states[:steps]))


@pytest.mark.parametrize("benchmark", ["pick_v1", "nav_v1"])
def test_action_space_is_the_robots_target_range(benchmark):
    """Bounded by what the robot clips targets to: a sampled action is commanded as is (no clipping)."""
    env = gym.make(f"molmo_lerobot/{benchmark}", horizon=2).unwrapped
    try:
        space = env.action_space
        assert np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high)) and np.all(space.low < space.high)
        names = env.features.action_names
        gripper = [i for i, n in enumerate(names) if "gripper" in n or "finger" in n]
        assert gripper and all((space.low[i], space.high[i]) == (0.0, 1.0) for i in gripper)
        env.reset(seed=0)
        sim = env._episode.env
        space.seed(3)
        for _ in range(5):
            action = space.sample()
            assert space.contains(action)
            for group, values in env.features.split_action(action.astype(np.float64)).items():
                sim.robot.command(sim.data, group, values)
                if group != "base":  # a base's yaw is taken within ±π of the current yaw
                    np.testing.assert_allclose(sim.robot.targets(sim.data, group), values, rtol=0, atol=1e-6)
            env.step(action)
        if benchmark == "nav_v1":
            assert names[:3] == ("base_x", "base_y", "base_theta")
            assert tuple(space.low[2:3]) == (np.float32(-np.pi),) and tuple(space.high[2:3]) == (np.float32(np.pi),)
    finally:
        env.close()
