"""policy=lerobot with a tiny ACT saved by save_pretrained and loaded by path (CPU, offline)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from lerobot.configs.types import FeatureType, PolicyFeature  # noqa: E402
from lerobot.policies.act.configuration_act import ACTConfig  # noqa: E402
from lerobot.policies.act.modeling_act import ACTPolicy  # noqa: E402
from lerobot.policies.factory import make_pre_post_processors  # noqa: E402

from molmo_lerobot.options import OptionsError  # noqa: E402
from molmo_lerobot.policies.base import EpisodeContext  # noqa: E402
from molmo_lerobot.policies.lerobot_policy import (  # noqa: E402
    LeRobotPolicy,
    WeightsNotLoadedError,
    verify_weights_loaded,
)

CHUNK = 4


def save_tiny_act(root, image_hw=(24, 32), state_dim=8) -> str:
    torch.manual_seed(0)
    cfg = ACTConfig(
        input_features={
            "observation.images.front": PolicyFeature(FeatureType.VISUAL, (3, *image_hw)),
            "observation.state": PolicyFeature(FeatureType.STATE, (state_dim,)),
        },
        output_features={"action": PolicyFeature(FeatureType.ACTION, (8,))},
        pretrained_backbone_weights=None,
        dim_model=32, n_heads=2, dim_feedforward=64, n_encoder_layers=1, n_decoder_layers=1,
        chunk_size=CHUNK, n_action_steps=CHUNK, use_vae=False, device="cpu",
    )
    policy = ACTPolicy(cfg)
    pre, post = make_pre_post_processors(cfg, dataset_stats=None)
    for obj in (policy, pre, post):
        obj.save_pretrained(root)
    return str(root)


@pytest.fixture(scope="module")
def act_dir(tmp_path_factory):
    return save_tiny_act(tmp_path_factory.mktemp("act"))


def ctx() -> EpisodeContext:
    return EpisodeContext(spec=None, episode_index=0, seed=0, prompt="pick the cube",
                          move_groups={"arm": 7, "gripper": 1}, policy_dt_s=0.066)


def obs(camera="front", hw=(48, 64)) -> dict:
    rng = np.random.default_rng(0)
    return {
        "images": {camera: rng.integers(0, 255, (*hw, 3), dtype=np.uint8)},
        "qpos": {"arm": np.linspace(-1, 1, 7), "gripper": np.array([0.5])},
        "prompt": "pick the cube",
    }


def test_step_mode_uses_action_queue(act_dir):
    policy = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu"})
    policy.reset(ctx())
    calls = []
    inner = policy.policy.predict_action_chunk
    policy.policy.predict_action_chunk = lambda b, **kw: calls.append(1) or inner(b, **kw)
    actions = [policy.act(obs()) for _ in range(CHUNK + 1)]
    assert all(a["arm"].shape == (7,) and a["gripper"].shape == (1,) for a in actions)
    assert len(calls) == 2  # one model call per chunk of CHUNK steps
    assert all(np.isfinite(a["arm"]).all() for a in actions)


def test_chunk_mode_returns_whole_chunk(act_dir):
    policy = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu", "mode": "chunk",
                            "cameras": {"wrist": "observation.images.front"}})
    policy.reset(ctx())
    out = policy.act(obs(camera="wrist"))
    assert out["arm"].shape == (CHUNK, 7) and out["gripper"].shape == (CHUNK, 1)
    step = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu"})
    step.reset(ctx())
    np.testing.assert_allclose(step.act(obs())["arm"], out["arm"][0], rtol=1e-5, atol=1e-6)


def test_frames_reach_the_policy_at_their_size_as_lerobot_eval_hands_them(act_dir):
    """By default (``resize=none``) the 48×64 frames reach a checkpoint declared at 24×32 as they are: the batch of
    one that LeRobot's ``preprocess_observation`` makes of the env's observation; ``pad`` resizes only when asked."""
    from lerobot.envs.utils import preprocess_observation

    seen = obs()
    policy = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu"})
    policy.reset(ctx())
    batch = policy._batch(seen)
    state = np.concatenate([seen["qpos"]["arm"], seen["qpos"]["gripper"]])
    theirs = preprocess_observation({"pixels": {"front": seen["images"]["front"][None]}, "agent_pos": state[None]})
    assert batch.keys() == {*theirs, "task"} and batch["task"] == ["pick the cube"]
    for key, value in theirs.items():
        assert value.shape == batch[key].shape and torch.equal(value, batch[key]), key
    assert policy.act(seen)["arm"].shape == (7,)
    padded = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu", "resize": "pad"})
    padded.reset(ctx())
    assert padded._batch(seen)["observation.images.front"].shape == (1, 3, 24, 32)


def test_loading_a_checkpoint_leaves_no_temporary_file(act_dir, tmp_path, monkeypatch):
    """LeRobot's config loading writes a temporary file it never removes; a load here leaves none."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu"})
    assert list(tmp_path.iterdir()) == [] and tempfile.tempdir == str(tmp_path)


def test_missing_camera_and_bad_state_are_clear(act_dir):
    policy = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu"})
    policy.reset(ctx())
    with pytest.raises(KeyError, match=r"wants camera 'front'.*policy.cameras"):
        policy.act(obs(camera="exo"))
    bad = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu", "state": ["arm"]})
    bad.reset(ctx())
    with pytest.raises(ValueError, match="needs 8 values"):
        bad.act(obs())


def test_molmospaces_convention_state_and_gripper_units(tmp_path):
    """convention=molmospaces: the state holds the gripper's two driver angles, the action's gripper is 0..255."""
    policy = LeRobotPolicy({"name": "lerobot", "path": save_tiny_act(tmp_path, state_dim=9), "device": "cpu",
                            "convention": "molmospaces"})
    policy.reset(ctx())
    native = {**obs(), "joint_qpos": {"arm": np.linspace(-1, 1, 7), "gripper": np.array([0.3, 0.31])},
              "joint_qvel": {"arm": np.zeros(7), "gripper": np.zeros(2)}, "tcp_pose": np.array([0, 0, 0, 1.0, 0, 0, 0]),
              "robot_base_pose": np.array([0, 0, 0, 1.0, 0, 0, 0])}
    state = policy._batch(native)["observation.state"][0].numpy()
    np.testing.assert_array_equal(state, np.float32([*np.linspace(-1, 1, 7), 0.3, 0.31]))
    assert policy.act(native)["arm"].shape == (7,)
    assert policy._to_action(np.array([[0.0] * 7 + [255.0]]))["gripper"][0] == 1.0


def test_bad_config_names_field(act_dir):
    with pytest.raises(ValueError, match=r"policy.mode"):
        LeRobotPolicy({"name": "lerobot", "path": act_dir, "mode": "sometimes"})
    with pytest.raises(OptionsError, match=r"^policy.path='/nonexistent/ckpt': no such directory$"):
        LeRobotPolicy({"name": "lerobot", "path": "/nonexistent/ckpt"})  # its options model checks the path


def test_refuses_checkpoint_whose_weights_did_not_load(act_dir, tmp_path):
    from safetensors.torch import load_file, save_file

    loaded = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu"})
    assert verify_weights_loaded(loaded.policy, f"{act_dir}/model.safetensors")["tensors"] > 10
    # Same checkpoint with every tensor renamed: from_pretrained (strict=False) silently keeps random weights.
    import shutil

    broken = tmp_path / "broken"
    shutil.copytree(act_dir, broken)
    tensors = load_file(broken / "model.safetensors")
    save_file({f"renamed_{k.replace('.', '_')}": v for k, v in tensors.items()}, broken / "model.safetensors")
    with pytest.raises(WeightsNotLoadedError, match="no counterpart"):
        LeRobotPolicy({"name": "lerobot", "path": str(broken), "device": "cpu"})
    # Weights present under the right names but not what the model holds.
    other = ACTPolicy(loaded.policy.config)
    with pytest.raises(WeightsNotLoadedError, match="differ from the checkpoint"):
        verify_weights_loaded(other, f"{act_dir}/model.safetensors")


# Batched serving (issue 17): forks share the model, keep their own queues; one forward per batch.
def varied_obs(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    return {"images": {"front": rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)},
            "qpos": {"arm": rng.uniform(-1, 1, 7), "gripper": rng.uniform(0, 1, 1)}, "prompt": "pick the cube"}


@pytest.mark.parametrize("mode", ["step", "chunk"])
def test_batched_forks_match_in_process_policies_per_client(act_dir, mode):
    cfg = {"name": "lerobot", "path": act_dir, "device": "cpu", "mode": mode}
    proto = LeRobotPolicy(cfg)
    assert proto.batched
    forks = [proto.fork() for _ in range(3)]
    alone = [LeRobotPolicy(cfg) for _ in range(3)]
    assert all(f.policy is proto.policy for f in forks)  # one model copy
    for p in forks + alone:
        p.reset(ctx())
    calls = []
    inner = proto.policy.predict_action_chunk
    proto.policy.predict_action_chunk = lambda b, **kw: calls.append(len(b["observation.state"])) or inner(b, **kw)
    for step in range(2 * CHUNK + 1):
        if step == 2:  # client 1 starts a new episode: only its queue is cleared
            forks[1].reset(ctx())
            alone[1].reset(ctx())
        observations = [varied_obs(10 * c + step) for c in range(3)]
        batched = LeRobotPolicy.act_batch(forks, observations)
        for c in range(3):
            expected = alone[c].act(observations[c])
            for g in ("arm", "gripper"):
                np.testing.assert_allclose(batched[c][g], expected[g], rtol=1e-4, atol=1e-5)
    if mode == "step":  # one forward per chunk for all clients together, client 1 once more after its reset
        assert calls == [3, 1, 2, 1, 2]
    else:
        assert calls == [3] * (2 * CHUNK + 1)


def test_single_fork_is_bit_identical_to_in_process(act_dir):
    cfg = {"name": "lerobot", "path": act_dir, "device": "cpu"}
    fork, alone = LeRobotPolicy(cfg).fork(), LeRobotPolicy(cfg)
    fork.reset(ctx())
    alone.reset(ctx())
    for step in range(CHUNK + 2):
        o = varied_obs(step)
        a, b = fork.act(o), alone.act(o)
        assert all(np.array_equal(a[g], b[g]) for g in a)


def test_bad_observation_in_a_batch_fails_only_its_item(act_dir):
    proto = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu"})
    forks = [proto.fork() for _ in range(3)]
    alone = LeRobotPolicy({"name": "lerobot", "path": act_dir, "device": "cpu"})
    for p in (*forks, alone):
        p.reset(ctx())
    bad = varied_obs(1)
    bad["images"] = {"exo": bad["images"]["front"]}
    out = LeRobotPolicy.act_batch(forks, [varied_obs(0), bad, varied_obs(2)])
    assert isinstance(out[1], KeyError) and "wants camera 'front'" in str(out[1])
    assert not forks[1]._queue  # its state is unchanged
    np.testing.assert_allclose(out[0]["arm"], alone.act(varied_obs(0))["arm"], rtol=1e-4, atol=1e-5)
    assert out[2]["arm"].shape == (7,)


def test_temporal_ensembling_is_not_batched(tmp_path):
    path = save_tiny_act(tmp_path / "te")
    from lerobot.configs.policies import PreTrainedConfig

    cfg = PreTrainedConfig.from_pretrained(path)
    cfg.temporal_ensemble_coeff, cfg.n_action_steps = 0.01, 1
    cfg.save_pretrained(path)
    policy = LeRobotPolicy({"name": "lerobot", "path": path, "device": "cpu"})
    assert not policy.batched and policy.fork() is None


def _with_relative_actions(policy: LeRobotPolicy) -> None:
    """Give ``policy`` pi0 / pi0.5's relative-action steps: the preprocessor caches the state,
    the postprocessor adds it back to the predicted offsets."""
    from lerobot.processor import AbsoluteActionsProcessorStep, RelativeActionsProcessorStep

    relative = RelativeActionsProcessorStep(enabled=True)
    policy.preprocessor.steps.insert(0, relative)
    policy.postprocessor.steps.append(AbsoluteActionsProcessorStep(enabled=True, relative_step=relative))


def test_relative_action_steps_batch_per_client(act_dir):
    """pi0 / pi0.5 keep the last state in their relative-action step between pre- and
    postprocessing; one batched call caches every client's state, so each gets its own offsets."""
    cfg = {"name": "lerobot", "path": act_dir, "device": "cpu", "mode": "chunk"}
    proto = LeRobotPolicy(cfg)
    _with_relative_actions(proto)
    forks = [proto.fork() for _ in range(3)]
    alone = [LeRobotPolicy(cfg) for _ in range(3)]
    for p in alone:
        _with_relative_actions(p)
    for p in forks + alone:
        p.reset(ctx())
    observations = [varied_obs(c) for c in range(3)]
    batched = LeRobotPolicy.act_batch(forks, observations)
    for c in range(3):
        expected = alone[c].act(observations[c])
        np.testing.assert_allclose(batched[c]["arm"], expected["arm"], rtol=1e-4, atol=1e-5)
    # the offsets really are relative: the same network output lands on each client's own state
    plain = LeRobotPolicy(cfg)
    plain.reset(ctx())
    shift = alone[0].act(observations[0])["arm"] - plain.act(observations[0])["arm"]
    np.testing.assert_allclose(shift, np.broadcast_to(observations[0]["qpos"]["arm"], shift.shape), atol=1e-5)


def test_pi0_family_is_batched():
    from molmo_lerobot.policies.lerobot_policy import BATCHABLE_TYPES

    assert {"act", "pi0", "pi05"} <= BATCHABLE_TYPES
