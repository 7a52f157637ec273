"""policy=pi0 remote mode against an openpi-style DROID server (no simulator).

Against MolmoSpaces' own PI_Policy: tests/parity/test_pi_policy.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from droid_server import FakeDroidServer

from molmo_lerobot.config import compose
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.image_ops import resize_with_pad
from molmo_lerobot.protocol.client import PolicyServerError, PolicyTimeoutError
from molmo_pi0.droid import DroidConfig, droid_actions
from molmo_pi0.plugin import make_pi0_policy

DT = 0.066


def ctx(prompt="pick up the mug") -> EpisodeContext:
    return EpisodeContext(spec=None, episode_index=3, seed=1, prompt=prompt,
                          move_groups={"arm": 7, "gripper": 1}, policy_dt_s=DT)


def obs(cams=("exo_camera_1", "wrist_camera"), hw=(120, 160)) -> dict:
    rng = np.random.default_rng(0)
    return {
        "images": {c: rng.integers(1, 255, (*hw, 3), dtype=np.uint8) for c in cams},
        "qpos": {"arm": np.arange(7) * 0.1, "gripper": np.array([0.25])},
        "joint_qpos": {"arm": np.arange(7) * 0.1, "gripper": np.array([0.2, 0.21])},
        "joint_qvel": {"arm": np.zeros(7), "gripper": np.zeros(2)},
        "tcp_pose": np.array([0.4, 0.0, 0.3, 0.0, 1.0, 0.0, 0.0]),
        "robot_base_pose": np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]),
        "step": 0,
    }


def pi0(port, preset="pi0_droid", **over):
    """``policy=<preset>`` as the CLI composes it, pointed at ``port``."""
    return make_pi0_policy({**compose([f"policy={preset}"])["policy"], "port": port, "timeout_s": 5, **over})


def test_letterbox_keeps_aspect_and_pads():
    img = np.full((120, 240, 3), 200, np.uint8)
    out = resize_with_pad(img, 224, 224)
    assert out.shape == (224, 224, 3) and out.dtype == np.uint8
    assert (out[:56] == 0).all() and (out[-56:] == 0).all() and (out[56:168] == 200).all()


def test_joint_velocity_is_integrated_and_gripper_mapped():
    raw = np.zeros((4, 8))
    raw[:, 0] = 1.0
    raw[:, 7] = [0.1, 0.6, 0.4, 0.9]
    q0 = np.zeros(7)
    velocity = DroidConfig(action_mode="joint_velocity", open_loop_horizon=None)
    out = droid_actions(raw, q0, velocity, DT, "test")
    np.testing.assert_allclose(out["arm"][:, 0], DT * np.arange(1, 5))
    np.testing.assert_array_equal(out["gripper"][:, 0], [0, 1, 0, 1])
    pos = droid_actions(raw, q0, DroidConfig(action_mode="joint_position", open_loop_horizon=2,
                                             gripper={"binarize": False}), DT, "test")
    assert pos["arm"].shape == (2, 7) and pos["arm"][0, 0] == 1.0 and pos["gripper"][1, 0] == 0.6
    with pytest.raises(ValueError, match=r"test: 'actions' has shape \(4, 5\)"):
        droid_actions(raw[:, :5], q0, velocity, DT, "test")


def test_gripper_threshold_compares_in_the_answers_float_type():
    """MolmoSpaces' PI_Policy compares a float32 answer with its threshold in float32: 0.3f is not
    above 0.3 (in float64 it is), so the gripper stays open; a float64 answer compares in float64."""
    cfg = DroidConfig(action_mode="joint_position", open_loop_horizon=None, gripper={"threshold": 0.3})
    raw = np.zeros((3, 8), np.float32)
    raw[:, 7] = [0.3, np.nextafter(np.float32(0.3), np.float32(1)), 0.29]
    assert droid_actions(raw, np.zeros(7), cfg, DT, "test")["gripper"][:, 0].tolist() == [0.0, 1.0, 0.0]
    assert droid_actions(raw.astype(np.float64), np.zeros(7), cfg, DT, "test")["gripper"][:, 0].tolist() == [1, 1, 0]


def test_remote_episode_chunks_come_from_the_server():
    with FakeDroidServer(horizon=15).running() as srv:
        policy = pi0(srv.port, open_loop_horizon=None)
        policy.reset(ctx())
        chunk = policy.act(obs())
        assert chunk["arm"].shape == (15, 7) and chunk["gripper"].shape == (15, 1)
        np.testing.assert_allclose(chunk["arm"][-1], np.arange(7) * 0.1 + 15 * 0.1 * DT, rtol=1e-6)
        policy.reset(ctx("put it down"))
        policy.act(obs())
        policy.close()
        assert srv.errors == [] and srv.connections == 1 and srv.requests == 2
    assert compose(["policy=pi0_droid"])["policy"]["open_loop_horizon"] == 8  # openpi's DROID client's


def test_camera_mapping_and_missing_camera():
    with FakeDroidServer(horizon=2).running() as srv:
        policy = pi0(srv.port, cameras={"exterior": "front", "wrist": "hand"})
        policy.reset(ctx())
        assert policy.act(obs(cams=("front", "hand")))["arm"].shape == (2, 7)
        with pytest.raises(KeyError, match=r"wrist camera.*'hand'.*set policy.cameras.wrist"):
            policy.act(obs(cams=("front", "exo")))
        assert srv.errors == []


@pytest.mark.parametrize("mode, error, match", [
    ("nan", ValueError, "non-finite value at step 1"),
    ("bad_shape", ValueError, r"shape \(10, 5\)"),
    ("silent", PolicyTimeoutError, "sent no inference response within 0.5 s"),
])
def test_bad_servers_become_clear_errors(mode, error, match):
    with FakeDroidServer(mode=mode).running() as srv:
        policy = pi0(srv.port, timeout_s=0.5)
        policy.reset(ctx())
        with pytest.raises(error, match=match):
            policy.act(obs())


def test_reset_message_to_openpi_server_surfaces_its_error():
    with FakeDroidServer().running() as srv:  # openpi servers know no reset endpoint
        policy = pi0(srv.port, reset="message")
        with pytest.raises(PolicyServerError, match="failed"):
            policy.reset(ctx())


def test_config_errors_name_the_field():
    with pytest.raises(ValueError, match=r"policy.action_mode"):
        make_pi0_policy({"name": "pi0", "action_mode": "torque"})
    with pytest.raises(ValueError, match=r"policy.colour"):
        make_pi0_policy({"name": "pi0", "colour": "red"})


def test_molmospaces_preset_sends_their_gripper_and_prompt_and_applies_targets():
    with FakeDroidServer(horizon=10).running() as srv:
        seen = []
        srv.answer = lambda request: seen.append(request) or FakeDroidServer.answer(srv, request)
        policy = pi0(srv.port, "pi0")
        policy.reset(ctx("Pick up the MUG"))
        chunk = policy.act(obs())
        assert chunk["arm"].shape == (8, 7) and (chunk["arm"] == np.float32(0.1)).all()  # absolute targets, 8 of 10
        assert seen[0]["prompt"] == "pick up the mug"
        assert seen[0]["observation/gripper_position"][0] == pytest.approx(0.2 / 0.824033)  # first driver angle
        with pytest.raises(KeyError, match=r"exterior camera: policy.cameras.exterior=\['droid_shoulder_light_rand"):
            policy.act(obs(cams=("front", "wrist_camera")))
        with pytest.raises(KeyError, match=r"convention=molmospaces needs \['joint_qpos'"):
            policy.act({k: v for k, v in obs().items() if k != "joint_qpos"})


@pytest.mark.parametrize("preset, checkpoint, use", [
    ("pi0", "gs://openpi-assets/checkpoints/pi05_droid", "policy=pi0_droid"),
    ("pi0_molmospaces", "pi0_fast_droid", "policy=pi0_droid"),
    ("pi0_droid", "/ckpt/pi05_droid_jointpos/", "policy=pi0_molmospaces"),
])
def test_checkpoint_of_the_other_action_space_is_refused(preset, checkpoint, use):
    with pytest.raises(ValueError, match=f"checkpoint '{checkpoint}'.*use {use}$"):
        pi0(0, preset, checkpoint=checkpoint)


def test_checkpoint_that_fits_is_accepted():
    with FakeDroidServer().running() as srv:
        pi0(srv.port, "pi0", checkpoint="pi05_droid_jointpos").close()
        pi0(srv.port, "pi0_droid", checkpoint="checkpoints/pi05_droid").close()
