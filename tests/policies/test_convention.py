"""policy.convention=molmospaces: MolmoSpaces' observation keys, units and frames, and their actions.

The observation side is checked on a real franka_droid / franka episode against the simulator's own
state; the pi0 presets built on it are checked against MolmoSpaces' PI_Policy in tests/parity.
"""

from __future__ import annotations

import json
from typing import ClassVar

import mujoco
import numpy as np
import pytest

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.policies.base import EpisodeContext, Policy
from molmo_lerobot.policies.convention import MolmoSpacesConvention, get_convention
from molmo_lerobot.policies.remote import RemotePolicy
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.serving.server import PolicyServer, serve_in_thread
from molmo_lerobot.sim.env import Timing

MS = MolmoSpacesConvention()


def episode_env(robot: str, gripper: list[float]):
    raw = json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())[0]
    raw["robot"] = {"robot_name": robot, "init_qpos": {"arm": [0, -0.7853, 0, -2.35619, 0, 1.57079, 0.0],
                                                       "gripper": gripper}}
    raw["task"]["robot_base_pose"] = [0.3, -0.2, 0.1, 0.9238795, 0.0, 0.0, 0.3826834]  # 45 deg about z
    raw["cameras"] = [c for c in raw["cameras"] if c["type"] == "exocentric"]  # the wrist mount differs per robot
    run = RunContext.build()
    env = build_env(parse_episode(raw, run.plugins), Timing(), run, None)
    env.reset(0)
    return env


def world_pose(pos, mat) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = np.reshape(mat, (3, 3)), pos
    return out


@pytest.mark.parametrize("robot, gripper, joints", [
    ("franka_droid", [0.3, 0.3], ["robot_0/gripper/left_driver_joint", "robot_0/gripper/right_driver_joint"]),
    ("franka", [0.01, 0.01], None),
])
def test_molmospaces_view_of_an_episode(robot, gripper, joints):
    env = episode_env(robot, gripper)
    try:
        obs = env.observe(images=False)
        view = MS.observation({**obs, "prompt": "pick up the mug"})
        m, d = env.model, env.data
        if joints:  # their qpos["gripper"]: the driver joints in rad, as the simulator has them
            assert view["qpos"]["gripper"] == np.float32([d.qpos[m.joint(j).qposadr[0]] for j in joints]).tolist()
        assert view["qpos"]["gripper"] == pytest.approx(gripper, abs=1e-6)
        assert view["qpos"]["arm"] == np.float32(obs["qpos"]["arm"]).tolist() and len(view["qvel"]["gripper"]) == 2
        # tcp_pose in the base frame: the TCP site's world pose seen from the episode's robot_base_pose
        base = np.eye(4)
        quat = np.array([0.9238795, 0.0, 0.0, 0.3826834])
        mat = np.zeros(9)
        mujoco.mju_quat2Mat(mat, quat / np.linalg.norm(quat))
        base[:3, :3], base[:3, 3] = mat.reshape(3, 3), [0.3, -0.2, 0.1]
        site = env.robot.tcp_site
        rel = np.linalg.inv(base) @ world_pose(d.site_xpos[site], d.site_xmat[site])
        got = np.zeros(9)
        mujoco.mju_quat2Mat(got, view["tcp_pose"][3:].astype(np.float64))
        np.testing.assert_allclose(view["tcp_pose"][:3], rel[:3, 3], atol=1e-6)
        np.testing.assert_allclose(got.reshape(3, 3), rel[:3, :3], atol=1e-6)
        assert view["tcp_pose"].dtype == np.float32 and view["task"] == "pick up the mug"
        np.testing.assert_allclose(view["robot_base_pose"], [0.3, -0.2, 0.1, *quat], atol=1e-6)
    finally:
        env.close()


def test_images_are_flat_per_camera_and_depth_suffixed():
    obs = {"images": {"exo_camera_1": np.zeros((4, 6, 3), np.uint8)},
           "depth": {"exo_camera_1": np.ones((4, 6), np.float32)},
           "joint_qpos": {"arm": np.zeros(7)}, "joint_qvel": {"arm": np.zeros(7)},
           "tcp_pose": np.array([1.0, 2, 3, 1, 0, 0, 0]), "robot_base_pose": np.array([1.0, 0, 0, 0, 0, 0, 1])}
    view = MS.observation(obs)
    assert sorted(view) == ["exo_camera_1", "exo_camera_1_depth", "qpos", "qvel", "robot_base_pose", "tcp_pose"]
    assert list(MS.images(view)) == ["exo_camera_1"]
    np.testing.assert_allclose(view["tcp_pose"][:3], [0.0, -2.0, 3.0], atol=1e-6)  # base at x=1, turned 180 deg about z
    with pytest.raises(KeyError, match=r"convention=molmospaces needs \['joint_qpos', 'joint_qvel'\]"):
        MS.observation({"qpos": {}, "tcp_pose": obs["tcp_pose"], "robot_base_pose": obs["robot_base_pose"]})


def test_their_actions_become_ours():
    step = MS.action({"arm": np.arange(7.0), "gripper": np.array([255.0]), "done": True})
    assert step["gripper"][0] == 1.0 and step["done"] is True and (step["arm"] == np.arange(7.0)).all()
    chunk = MS.action([{"arm": np.zeros(7), "gripper": np.array([0.0])},
                       {"arm": np.ones(7), "gripper": np.array([127.5])}])
    assert chunk["arm"].shape == (2, 7) and chunk["gripper"][:, 0].tolist() == [0.0, 0.5]
    assert get_convention("native").action(step) is step
    with pytest.raises(ValueError, match=r"policy.convention='droid'"):
        get_convention("droid")
    with pytest.raises(ValueError, match="non-empty list of dicts"):
        MS.action([])


class EchoTheirs(Policy):
    """A served policy written against MolmoSpaces' observations: holds the arm, closes the gripper (255)."""

    needs_images = True
    seen: ClassVar[list[dict]] = []

    def reset(self, ctx):
        pass

    def act(self, obs):
        EchoTheirs.seen.append(obs)
        return {"arm": np.asarray(obs["qpos"]["arm"]), "gripper": np.array([255.0])}


def test_remote_policy_speaks_their_convention_on_the_wire():
    server = PolicyServer(EchoTheirs, port=0, metadata={"server": "molmo-serve", "policy": "echo"})
    native = {"images": {"wrist_camera": np.full((4, 4, 3), 7, np.uint8)},
              "qpos": {"arm": np.arange(7.0), "gripper": [0.5]},
              "joint_qpos": {"arm": np.arange(7.0), "gripper": np.array([0.4, 0.4])},
              "joint_qvel": {"arm": np.zeros(7), "gripper": np.zeros(2)},
              "tcp_pose": np.array([0.5, 0, 0.2, 1, 0, 0, 0]), "robot_base_pose": np.array([0.0, 0, 0, 1, 0, 0, 0]),
              "prompt": "pick", "step": 0}
    with serve_in_thread(server) as srv:
        policy = RemotePolicy({"name": "remote", "port": srv.port, "timeout_s": 5, "convention": "molmospaces"})
        policy.reset(EpisodeContext(spec=None, episode_index=0, seed=0, prompt="pick",  # type: ignore[arg-type]
                                    move_groups={"arm": 7, "gripper": 1}, policy_dt_s=0.066))
        action = policy.act(native)
        policy.close()
    got = EchoTheirs.seen[-1]
    assert (got["wrist_camera"] == 7).all() and got["qpos"]["gripper"] == pytest.approx([0.4, 0.4])
    assert got["task"] == "pick"
    assert "images" not in got and action["gripper"][0] == 1.0 and (action["arm"] == np.arange(7.0)).all()


def test_any_other_policy_plugin_is_wrapped(tmp_path):
    """policy=replay policy.convention=molmospaces replays MolmoSpaces-unit actions (gripper 0 … 255)."""
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.policies.convention import ConventionAdapter
    from molmo_lerobot.policies.factory import make_policy

    np.save(tmp_path / "a.npy", np.array([[0.1] * 7 + [255.0], [0.2] * 7 + [51.0]]))
    plugins = Plugins()
    policy = make_policy(plugins, {"name": "replay", "actions": str(tmp_path / "a.npy"), "convention": "molmospaces"})
    assert isinstance(policy, ConventionAdapter) and policy.needs_images is False
    policy.reset(EpisodeContext(spec=None, episode_index=0, seed=0, prompt="", move_groups={"arm": 7, "gripper": 1},  # type: ignore[arg-type]
                                policy_dt_s=0.066))
    obs = {"qpos": {"arm": np.zeros(7)}, "joint_qpos": {"arm": np.zeros(7)}, "joint_qvel": {"arm": np.zeros(7)},
           "tcp_pose": np.array([0, 0, 0, 1.0, 0, 0, 0]), "robot_base_pose": np.array([0, 0, 0, 1.0, 0, 0, 0])}
    assert [policy.act(obs)["gripper"][0] for _ in range(2)] == [1.0, 0.2]
    native = make_policy(plugins, {"name": "replay", "actions": str(tmp_path / "a.npy"), "convention": "native"})
    assert not isinstance(native, ConventionAdapter)
