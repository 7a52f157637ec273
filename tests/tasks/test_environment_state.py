"""The opt-in, privileged ``observation.environment_state``: pick's object pose in the robot base
frame, its half extents and the TCP-to-object vector, one vector through the feature map for the
recorder, the Gymnasium env and policy=lerobot; recorded only when asked for; a checkpoint trained
on it gets it at evaluation."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS
from molmo_lerobot.config import compose
from molmo_lerobot.export.frames import FrameLayout
from molmo_lerobot.features import ACTION, ENV_STATE, ENV_STATE_KEY, STATE, FeatureError, FeatureMap
from molmo_lerobot.gym_env import MolmoEnv
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.poses import pose_matrix
from molmo_lerobot.recording import EpisodeInfo
from molmo_lerobot.runner.evaluate import run_evaluation

NAMES = ["object_x", "object_y", "object_z", "object_qw", "object_qx", "object_qy", "object_qz",
         "object_half_x", "object_half_y", "object_half_z", "tcp_to_object_x", "tcp_to_object_y", "tcp_to_object_z"]
#: one recorded step-3 pick_v1 episode (episode 0)
STATE_RUN = ["benchmark=pick_v1", "limit=1", "workers=1", "horizon=3", "record=true", "progress=false"]


def _tiny_state_act(root, fmap: FeatureMap) -> str:
    """A LeRobot ACT on ``observation.state`` + ``observation.environment_state`` only (as lerobot-train makes it)."""
    torch = pytest.importorskip("torch")
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors

    torch.manual_seed(0)
    inputs = {STATE: PolicyFeature(FeatureType.STATE, (fmap.state_dim,)),
              ENV_STATE: PolicyFeature(FeatureType.ENV, (len(fmap.env_state_names),))}
    cfg = ACTConfig(input_features=inputs, output_features={ACTION: PolicyFeature(FeatureType.ACTION,
                                                                                  (fmap.action_dim,))},
                    pretrained_backbone_weights=None, dim_model=16, n_heads=2, dim_feedforward=32, n_encoder_layers=1,
                    n_decoder_layers=1, chunk_size=2, n_action_steps=2, use_vae=False, device="cpu")
    pre, post = make_pre_post_processors(cfg, dataset_stats=None)
    for obj in (ACTPolicy(cfg), pre, post):
        obj.save_pretrained(root)
    return str(root)


@pytest.fixture(scope="module")
def genv():
    env = MolmoEnv("pick_v1", episode_index=3, horizon=4, environment_state=True)
    yield env
    env.close()


def test_pick_state_is_the_object_pose_size_and_offset_in_the_base_frame(genv):
    obs, _ = genv.reset()
    state = obs[ENV_STATE_KEY]
    assert state.dtype == np.float32 and state.shape == (13,) and state[3] >= 0
    assert genv.features.env_state_names == tuple(NAMES)
    ep = genv._episode
    base = pose_matrix(ep.env.base_pose)
    world = base @ pose_matrix(state[:7].astype(np.float64))
    body = ep.task._object
    np.testing.assert_allclose(world[:3, 3], ep.env.data.xpos[body], atol=1e-5)
    np.testing.assert_allclose(world[:3, :3], ep.env.data.xmat[body].reshape(3, 3), atol=1e-5)
    # the half extents are the builtin object's own (a turned object keeps them: its own frame)
    np.testing.assert_allclose(state[7:10], BUILTIN_OBJECTS[ep.task.object_name].half_extents, atol=1e-6)
    tcp = ep.env.data.site_xpos[ep.env.robot.tcp_site]
    np.testing.assert_allclose(base[:3, :3] @ state[10:], ep.env.data.xpos[body] - tcp, atol=1e-5)


def test_recorder_env_and_policy_see_the_same_vector(genv, tmp_path):
    from molmo_lerobot.policies.lerobot_policy import LeRobotPolicy

    genv.reset()
    genv.step(genv.action_space.sample() * 0 + genv._obs(genv._episode.observe())["agent_pos"])  # hold: a later state
    obs = genv._episode.observe()
    ep = genv._episode
    info = EpisodeInfo(identity=ep.plan.identity, fps=15.0, camera_names=list(ep.env.camera_names),
                       img_resolution=(224, 224),
                       joint_names=dict(ep.env.joint_names), move_groups=dict(ep.env.move_groups),
                       environment_state_names=ep.task.environment_state_names)
    layout = FrameLayout.from_step(info, obs, None)
    assert layout.feature_map == genv.features
    assert layout.features()[ENV_STATE] == {"dtype": "float32", "shape": (13,), "names": NAMES}
    qpos = ep.env.observe(images=False)["qpos"]
    recorded = layout.frame(obs, qpos, None, False, False, ep.plan.prompt, info)[ENV_STATE]
    np.testing.assert_array_equal(genv._obs(obs)[ENV_STATE_KEY], recorded)
    policy = LeRobotPolicy({"name": "lerobot", "path": _tiny_state_act(tmp_path / "act", genv.features),
                            "device": "cpu"})
    assert policy.needs_environment_state and not policy.needs_images
    policy.reset(EpisodeContext(spec=None, episode_index=0, seed=0, prompt=ep.plan.prompt,
                                move_groups=dict(ep.env.move_groups), policy_dt_s=0.066))
    np.testing.assert_array_equal(policy._batch(obs)[ENV_STATE][0].numpy(), recorded)
    with pytest.raises(KeyError, match=r"observation\.environment_state"):
        policy._batch({k: v for k, v in obs.items() if k != ENV_STATE_KEY})
    with pytest.raises(FeatureError, match=r"observation.environment_state: 3 values, expected 13"):
        layout.frame({**obs, ENV_STATE_KEY: np.zeros(3)}, {}, None, False, False, "", info)


def _first_recorded_state(out):
    """The recording's ``observation.environment_state`` names and its first frame's value."""
    root = out / "dataset"
    feats = json.loads((root / "meta" / "info.json").read_text())["features"]
    frames = pd.concat(pd.read_parquet(p) for p in sorted((root / "data").rglob("*.parquet")))
    return feats[ENV_STATE], frames.sort_values("frame_index").iloc[0][ENV_STATE]


def _episode_0_state() -> tuple[np.ndarray, FeatureMap]:
    """pick_v1 episode 0's first environment state through the Gymnasium env (the same trial as a run's)."""
    genv = MolmoEnv("pick_v1", episode_index=0, horizon=3, environment_state=True)
    try:
        return genv.reset()[0][ENV_STATE_KEY], genv.features
    finally:
        genv.close()


def test_recorded_only_when_asked_and_a_state_policy_gets_it(tmp_path, pick_recording, fork_servers):
    """A checkpoint that reads it gets it at evaluation with no option set, and the recording holds what
    it saw (the env's own values); a run that nobody asks for it records none. The option asking for it
    is the slow test below (and the error when a task has none, in the default run)."""
    first, fmap = _episode_0_state()
    act = _tiny_state_act(tmp_path / "act", fmap)
    res = run_evaluation(compose([f"policy.path={act}", "policy=lerobot", "policy.device=cpu", *STATE_RUN,
                                  f"output_dir={tmp_path / 'policy'}"]), fork_servers)
    assert res.summary["n_errors"] == 0
    feature, recorded = _first_recorded_state(tmp_path / "policy")
    assert feature["names"] == NAMES and feature["shape"] == [13]
    np.testing.assert_array_equal(first, recorded)
    off, _, _ = pick_recording  # the scripted expert recorded without the option
    assert ENV_STATE not in json.loads((off / "dataset" / "meta" / "info.json").read_text())["features"]


@pytest.mark.slow
def test_the_option_records_it_for_a_policy_that_does_not_read_it(tmp_path):
    run_evaluation(compose(["policy=scripted", *STATE_RUN, "record_environment_state=true",
                            f"output_dir={tmp_path / 'on'}"]))
    feature, recorded = _first_recorded_state(tmp_path / "on")
    assert feature["names"] == NAMES and feature["shape"] == [13]
    np.testing.assert_array_equal(_episode_0_state()[0], recorded)


@pytest.mark.slow
def test_a_served_state_policy_is_sent_the_state_too(tmp_path):
    genv = MolmoEnv("pick_v1", episode_index=0, horizon=3, environment_state=True)
    try:
        fmap = genv.features
    finally:
        genv.close()
    act = _tiny_state_act(tmp_path / "act", fmap)
    args = [f"policy.path={act}", "policy=lerobot", "policy.device=cpu", "benchmark=pick_v1", "limit=1", "workers=1",
            "horizon=3", "progress=false"]
    res = run_evaluation(compose([*args, f"output_dir={tmp_path / 'policy'}"]))
    served = run_evaluation(compose([*args, "policy.serve=true", f"output_dir={tmp_path / 'served'}"]))
    assert res.summary["n_errors"] == 0 and served.summary["n_errors"] == 0
    assert [e.success for e in served.episodes] == [e.success for e in res.episodes]


def test_a_task_without_environment_state_is_an_episode_error(tmp_path, fork_servers):
    res = run_evaluation(compose(["policy=scripted", "benchmark=open_v1", "limit=1", "workers=1", "horizon=2",
                                  "progress=false", "record_environment_state=true", f"output_dir={tmp_path}"]),
                         fork_servers)
    lines = [json.loads(x) for x in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    assert res.summary["n_errors"] == 1
    assert "defines no environment state (asked for by record_environment_state=true)" in lines[0]["error"]
