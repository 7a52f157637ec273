"""One feature map: a recorded run's features are the map's, every adapter names and orders the same
arrays (recorder, Gymnasium env, --env.type=molmo, policy=lerobot, policy=replay, the DROID request),
and a mobile robot's extra move group needs no code."""

from __future__ import annotations

import json
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from molmo_lerobot.export.frames import FrameLayout
from molmo_lerobot.features import ACTION, STATE, FeatureError, FeatureMap, image_feature
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.recording import EpisodeInfo
from molmo_lerobot.results import EpisodeIdentity
from molmo_lerobot.robots.franka_droid import FrankaDroid
from molmo_lerobot.run_config import RunConfig

#: the cameras franka_droid's DROID camera system builds, in its order
DROID_CAMERAS = ["wrist_camera", "exo_camera_1"]
STEPS = 3


class MobileRobot:
    """The feature side of a robot descriptor (``RobotType``) with a mobile base as its first move group."""

    name = "mobile_franka"
    move_groups: ClassVar[dict[str, int]] = {"base": 3, "arm": 7, "gripper": 1}
    joint_names: ClassVar[dict[str, list[str]]] = {"base": ["base_x", "base_y", "base_yaw"],
                                                   "arm": [f"joint{k}" for k in range(1, 8)], "gripper": ["gripper"]}


def _jsonable(features: dict) -> dict:
    return json.loads(json.dumps(features))


def _observation(fmap: FeatureMap, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    return {"images": {c: rng.integers(0, 255, (h, w, 3), dtype=np.uint8) for c, h, w in fmap.cameras},
            "qpos": {g: rng.uniform(0, 1, n) for g, n in zip(fmap.groups, fmap.state_sizes, strict=True)},
            "prompt": "pick up the mug"}


def _action(fmap: FeatureMap, seed: int = 1) -> dict:
    rng = np.random.default_rng(seed)
    return {g: rng.uniform(0, 1, n) for g, n in fmap.move_groups.items()}


def _info(fmap: FeatureMap, robot: str, steps: int = STEPS) -> EpisodeInfo:
    return EpisodeInfo(identity=EpisodeIdentity(0, 7, "pick", "pick up the mug", steps, "cli", "", house_index=0),
                       fps=15.0, camera_names=[c for c, _, _ in fmap.cameras],
                       img_resolution=(fmap.cameras[0][2], fmap.cameras[0][1]),
                       joint_names={g: list(n) for g, n in MobileRobot.joint_names.items()} if robot == MobileRobot.name
                       else dict(FrankaDroid.joint_names),
                       move_groups=fmap.move_groups, extra={"robot": robot})


def _tiny_act(root: Path, fmap: FeatureMap) -> str:
    """A LeRobot ACT with our dataset's features as its inputs and output (as lerobot-train makes it)."""
    torch = pytest.importorskip("torch")
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors

    torch.manual_seed(0)
    inputs = {image_feature(c): PolicyFeature(FeatureType.VISUAL, (3, h, w)) for c, h, w in fmap.cameras}
    inputs[STATE] = PolicyFeature(FeatureType.STATE, (fmap.state_dim,))
    outputs = {ACTION: PolicyFeature(FeatureType.ACTION, (fmap.action_dim,))}
    cfg = ACTConfig(input_features=inputs, output_features=outputs,
                    pretrained_backbone_weights=None, dim_model=16, n_heads=2, dim_feedforward=32, n_encoder_layers=1,
                    n_decoder_layers=1, chunk_size=2, n_action_steps=2, use_vae=False, device="cpu")
    pre, post = make_pre_post_processors(cfg, dataset_stats=None)
    for obj in (ACTPolicy(cfg), pre, post):
        obj.save_pretrained(root)
    return str(root)


def _lerobot_policy(root: Path, fmap: FeatureMap):
    from molmo_lerobot.policies.lerobot_policy import LeRobotPolicy

    policy = LeRobotPolicy({"name": "lerobot", "path": _tiny_act(root, fmap), "device": "cpu"})
    policy.reset(EpisodeContext(spec=None, episode_index=0, seed=0, prompt="pick up the mug",
                                move_groups=fmap.move_groups, policy_dt_s=0.066))
    return policy


def _assert_parts_equal(got: dict, expected: dict) -> None:
    assert list(got) == list(expected)
    for g, values in expected.items():
        np.testing.assert_array_equal(np.asarray(got[g]), np.asarray(values))


@pytest.fixture(scope="module")
def droid_run(droid_recording):
    """franka_droid with its DROID cameras, recorded by molmo-eval: (benchmark dir, dataset root, feature map)."""
    bench, out, res, _ = droid_recording
    assert res.summary["n_errors"] == 0
    width, height = json.loads((bench / "benchmark.json").read_text())[0]["img_resolution"]
    fmap = FeatureMap.build(FrankaDroid.move_groups, FrankaDroid.joint_names,
                            [(c, height, width) for c in DROID_CAMERAS])
    return bench, out / "dataset", fmap


def test_a_recorded_run_has_the_feature_maps_features(droid_run):
    _, root, fmap = droid_run
    info = json.loads((root / "meta" / "info.json").read_text())
    recorded = {k: {f: v[f] for f in ("dtype", "shape", "names")} for k, v in info["features"].items()
                if k.startswith("observation.") or k == ACTION}
    assert recorded == _jsonable(fmap.features())
    assert list(recorded) == ["observation.images.wrist_camera", "observation.images.exo_camera_1", STATE, ACTION]
    names = [*(f"fr3_joint{k}" for k in range(1, 8)), "robotiq_gripper"]
    assert recorded[STATE]["names"] == names == recorded[ACTION]["names"]


def test_the_adapters_agree_on_franka_droid_with_droid_cameras(droid_run, tmp_path):
    import pandas as pd

    from molmo_lerobot.gym_env import MolmoEnv
    from molmo_pi0.droid import (
        DROID,
        EXTERIOR,
        GRIPPER,
        JOINTS,
        WRIST,
        DroidConfig,
        droid_actions,
        droid_request,
        pick_cameras,
    )

    bench, root, fmap = droid_run
    obs, action = _observation(fmap), _action(fmap)
    # the recorder
    frame = FrameLayout.from_step(_info(fmap, "franka_droid"), obs, None).frame(
        obs, action, None, False, False, "pick up the mug", _info(fmap, "franka_droid"))
    # the Gymnasium env: its map is the descriptor's; its first agent_pos is the recorded first state
    genv = MolmoEnv(str(bench), horizon=STEPS)
    try:
        assert genv.features == fmap
        first, _ = genv.reset(seed=0)
        assert {c: b.shape for c, b in genv.observation_space["pixels"].items()} == fmap.camera_shapes
        assert genv.observation_space["agent_pos"].shape == (fmap.state_dim,)
        assert genv.action_space.shape == (fmap.action_dim,)
        np.testing.assert_array_equal(genv._obs(obs)["agent_pos"], frame[STATE])
    finally:
        genv.close()
    frames = pd.concat(pd.read_parquet(p) for p in sorted((root / "data").rglob("*.parquet")))
    episode_0 = frames[frames["episode_index"] == 0]  # benchmark episode 0, the env's on reset(seed=0)
    np.testing.assert_array_equal(episode_0.sort_values("frame_index").iloc[0][STATE], first["agent_pos"])
    # lerobot-eval's env (--env.type=molmo) maps its keys onto the recorded features
    lerobot_env = pytest.importorskip("lerobot_env_molmo")
    cfg = lerobot_env.MolmoEnvConfig(task=str(bench), horizon=STEPS)
    assert {cfg.features_map[k]: tuple(f.shape) for k, f in cfg.features.items()} == {
        **{image_feature(c): s for c, s in fmap.camera_shapes.items()},
        STATE: (fmap.state_dim,), ACTION: (fmap.action_dim,)}
    # policy=lerobot, trained on those features: the same images, state vector and action split
    policy = _lerobot_policy(tmp_path / "act", fmap)
    batch = policy._batch(obs)
    np.testing.assert_array_equal(batch[STATE][0].numpy(), frame[STATE])
    for c, _, _ in fmap.cameras:
        np.testing.assert_array_equal(batch[image_feature(c)][0].permute(1, 2, 0).mul(255).round().byte().numpy(),
                                      frame[image_feature(c)])
    _assert_parts_equal(policy._to_action(frame[ACTION][None].astype(np.float64)),
                        {g: np.float32(a) for g, a in action.items()})
    # the DROID request and actions: franka's move groups, the recorded state's values
    assert DROID.move_groups == fmap.move_groups
    native = DroidConfig(convention="native", cameras={}, gripper={"obs_closed": 1.0, "binarize": False})
    assert pick_cameras(native.cameras, list(obs["images"])) == ("exo_camera_1", "wrist_camera")
    request = droid_request(obs["images"], obs["qpos"], "pick up the mug", native)
    assert {EXTERIOR, WRIST} <= set(request)
    np.testing.assert_array_equal(np.float32(np.concatenate([request[JOINTS], request[GRIPPER]])), frame[STATE])
    _assert_parts_equal(droid_actions(frame[ACTION][None], request[JOINTS], native, 0.066, "test"),
                        {"arm": frame[ACTION][None, :7], "gripper": frame[ACTION][None, 7:]})


def test_a_mobile_base_is_one_more_move_group(tmp_path):
    from molmo_lerobot.export.recorder import LeRobotRecorderFactory
    from molmo_lerobot.policies.replay import ReplayPolicy
    from molmo_lerobot.results import EpisodeResult, summarize

    fmap = FeatureMap.build(MobileRobot.move_groups, MobileRobot.joint_names,
                            [("head/rgb", 24, 32), ("wrist", 24, 32)])  # "/": recorded as head_rgb
    assert fmap.groups == ("base", "arm", "gripper") and fmap.action_layout() == "base (3) + arm (7) + gripper (1)"
    assert fmap.state_names[:4] == ("base_x", "base_y", "base_yaw", "joint1")
    assert fmap.action_dim == fmap.state_dim == 11
    assert list(fmap.features()) == ["observation.images.head_rgb", "observation.images.wrist", STATE, ACTION]
    obs, action = _observation(fmap), _action(fmap)
    cams = ["head/rgb", "wrist"]
    assert FeatureMap.from_observation(MobileRobot.move_groups, MobileRobot.joint_names, cams, obs) == fmap
    state = fmap.state_vector(obs["qpos"])
    np.testing.assert_array_equal(state[:3], np.float32(obs["qpos"]["base"]))
    vector = fmap.action_vector(action)
    _assert_parts_equal(fmap.split_action(vector), {g: np.float32(a) for g, a in action.items()})
    with pytest.raises(FeatureError, match="action: move group 'base' missing"):
        fmap.action_vector({g: a for g, a in action.items() if g != "base"})

    # recorded: the dataset's features are the map's
    factory = LeRobotRecorderFactory.from_config(RunConfig.of({
        "benchmark": {"name": "mobile_v1"}, "policy": {"name": "scripted"}, "timing": {"policy_dt_ms": 66.0},
        "hub": {"repo_id": None, "private": False}, "push": False}))
    rec = factory.make("w0g0", tmp_path)
    info = _info(fmap, MobileRobot.name)
    rec.start_episode(info)
    for t in range(STEPS):
        rec.record_step(_observation(fmap, t), action, None, False, t == STEPS - 1)
    result = EpisodeResult(0, 0, "molmo.tasks.Pick", False, False, STEPS, info.seed, task_type="pick",
                           prompt=info.prompt, horizon=STEPS)
    rec.end_episode(result)
    rec.close()
    bench = {"name": "mobile_v1", "sha256": "ab" * 32, "n_episodes": 1}
    factory.finalize(tmp_path, [result], summarize([result], benchmark=bench, policy={"name": "scripted"}, seed=0))
    features = json.loads((tmp_path / "dataset" / "meta" / "info.json").read_text())["features"]
    recorded = {k: {f: features[k][f] for f in ("dtype", "shape", "names")} for k in fmap.features()}
    assert recorded == _jsonable(fmap.features())

    # policy=lerobot by default reads the episode's move groups in order; policy=replay splits the same way
    policy = _lerobot_policy(tmp_path / "act", fmap)
    np.testing.assert_array_equal(policy._batch(obs)[STATE][0].numpy(), state)
    _assert_parts_equal(policy._to_action(vector[None].astype(np.float64)), fmap.split_action(vector))
    np.save(tmp_path / "actions.npy", vector[None])
    replay = ReplayPolicy({"actions": str(tmp_path / "actions.npy")})
    replay.reset(EpisodeContext(spec=None, episode_index=0, seed=0, prompt="", move_groups=fmap.move_groups,
                                policy_dt_s=0.066))
    _assert_parts_equal(replay.act(obs), fmap.split_action(vector))
