"""MolmoSpaces' side of tests/parity/test_rollout_parity.py: whole episodes through their own rollout loop.

For each episode: their ``CPUMujocoEnv`` over the compiled episode model our side sends (an MJB of the
scene, objects and arm as ``molmo-eval`` builds it, body sleeping off), their ``FrankaRobot`` (robot view,
``JointPosController`` s), their ``JsonEvalTaskSampler.randomize_scene`` and ``_sample_task`` (state from
the episode spec, task class and config from their ``EpisodeSpec``), then their
``ParallelRolloutRunner.run_single_rollout``, unmodified, with a policy that replays the given actions
(their convention: ``arm`` joint targets, ``gripper`` 0 … 255). The policy reads the state each time
their loop asks it for an action, so the states after steps 0 … T-1 come back, then the final one.

Substituted, because it cannot run on our model or here:

* the robot base group: theirs is a mocap body moved after compiling; ours is built at the pose as a
  static body. Their ``ImmobileRobotBaseGroup`` reads it; setting its pose (``_sample_task`` sets
  ``robot_base_pose``) checks that the base is already there (1e-9 m) instead of moving it;
* the gripper group's two pad geoms (``gripper/left_pad2``, ``right_pad2``, read only for the finger
  distance sensor) are our arm's ``left_fingerpad_collision`` / ``right_fingerpad_collision``;
* their robot directory (gated) holds our arm's MJCF, as in the placement tests; their kinematics
  solvers are built from it;
* the grasp-library look-up (``get_joint_grasp_path``): their sampler applies an articulated object's
  ``joint_start_position`` only where the joint has a grasp file in their downloaded library; here
  every joint has one;
* downloaded resources (``theirs.offline``).

Their renderer is theirs (``MjOpenGLRenderer`` through MuJoCo's GL context, EGL here), counting its frames:
an episode's recorded cameras are rendered at every observation their loop makes.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np
from theirs import offline

offline()

import molmo_spaces.env.env as their_env  # noqa: E402
import molmo_spaces.evaluation  # noqa: E402,F401  (their import order: evaluation before the sampler)
import molmo_spaces.utils.grasps as their_grasps  # noqa: E402
from molmo_spaces.configs.policy_configs import BasePolicyConfig  # noqa: E402
from molmo_spaces.configs.robot_configs import FrankaRobotConfig  # noqa: E402
from molmo_spaces.data_generation.pipeline import ParallelRolloutRunner  # noqa: E402
from molmo_spaces.env.env import CPUMujocoEnv  # noqa: E402
from molmo_spaces.evaluation.benchmark_schema import EpisodeSpec  # noqa: E402
from molmo_spaces.evaluation.configs.evaluation_configs import JsonBenchmarkEvalConfig  # noqa: E402
from molmo_spaces.policy.base_policy import BasePolicy  # noqa: E402
from molmo_spaces.robots.robot_views.abstract import GripperGroup, ImmobileRobotBaseGroup  # noqa: E402
from molmo_spaces.robots.robot_views.franka_droid_view import (  # noqa: E402
    FrankaDroidRobotView,
    RobotIQGripperGroup,
)
from molmo_spaces.robots.robot_views.franka_fr3_view import FrankaFR3ArmGroup  # noqa: E402
from molmo_spaces.tasks.json_eval_task_sampler import JsonEvalTaskSampler  # noqa: E402


class _CountingRenderer(their_env.MjOpenGLRenderer):
    """Their OpenGL renderer, counting the frames it renders."""

    frames = 0

    def render(self, *args, **kwargs):
        _CountingRenderer.frames += 1
        return super().render(*args, **kwargs)


their_env.MjOpenGLRenderer = _CountingRenderer
their_env.HAS_FILAMENT = False  # their classic renderer, as without the filament package
# their sampler sets an articulated object's joint_start_position only on joints that have a grasp file
# in their (downloaded) grasp library: every joint has one here
their_grasps.get_joint_grasp_path = lambda asset_id, joint_name: Path(f"{asset_id}/{joint_name}.npz")


class _BuiltBase(ImmobileRobotBaseGroup):
    """Their immobile base group; setting the pose checks the base is already there."""

    def __init__(self, mj_data, namespace: str = "") -> None:
        super().__init__(mj_data, mj_data.model.body(f"{namespace}base").id)

    @property
    def pose(self) -> np.ndarray:
        return super().pose

    @pose.setter
    def pose(self, pose: np.ndarray) -> None:
        mujoco.mj_kinematics(self.mj_model, self.mj_data)
        if not np.allclose(self.pose, pose, atol=1e-9):
            raise ValueError(f"robot base at {self.pose.tolist()}, episode wants {np.asarray(pose).tolist()}")


class _Gripper(RobotIQGripperGroup):
    """Their Robotiq group; its pad geoms are our arm's finger pads."""

    def __init__(self, mj_data, base_group, namespace: str = "") -> None:
        model = mj_data.model
        self._namespace = namespace
        joints = [model.joint(f"{namespace}gripper/{s}_driver_joint").id for s in ("left", "right")]
        GripperGroup.__init__(self, mj_data, joints, [model.actuator(f"{namespace}gripper/fingers_actuator").id],
                              model.body(f"{namespace}gripper/base").id, base_group)
        self._ee_site_id = model.site(f"{namespace}gripper/grasp_site").id
        self._finger_1_geom_id = model.geom(f"{namespace}gripper/left_fingerpad_collision").id
        self._finger_2_geom_id = model.geom(f"{namespace}gripper/right_fingerpad_collision").id


class _View(FrankaDroidRobotView):
    """Their ``FrankaDroidRobotView`` with the base and gripper groups above; the arm group is theirs."""

    def __init__(self, mj_data, namespace: str = "") -> None:
        self._namespace = namespace
        base = _BuiltBase(mj_data, namespace)
        groups = {"base": base,
                  "arm": FrankaFR3ArmGroup(mj_data, base, namespace=namespace, grasp_site_name="gripper/grasp_site"),
                  "gripper": _Gripper(mj_data, base, namespace)}
        super(FrankaDroidRobotView, self).__init__(mj_data, groups)


class Replay(BasePolicy):
    """Replays ``actions`` (T, 8: arm 7, gripper 0 … 255), one per call; records the state each call."""

    actions: np.ndarray = np.zeros((0, 8))

    def __init__(self, config, task=None) -> None:
        super().__init__(config, task)
        self.t = 0
        self.states: list[np.ndarray] = []

    def reset(self) -> None:
        self.t = 0
        self.states = []

    def get_action(self, observation):
        data = self.task.env.current_data
        self.states.append(_state(data))
        a = self.actions[self.t]
        self.t += 1
        return {"arm": a[:7].copy(), "gripper": a[7:8].copy()}


def _state(data) -> np.ndarray:
    return np.concatenate([data.qpos, data.qvel])


def _robot_dir(root: Path, xml: str) -> None:
    """Their robot dir with our arm; its bodies' inertias written out, so that their kinematics models
    (built with the meshes stripped) keep the masses the meshes gave."""
    spec = mujoco.MjSpec.from_string(xml)
    model = spec.compile()
    for body in spec.bodies[1:]:
        b = model.body(body.name).id
        body.explicitinertial = True
        body.mass, body.inertia = float(model.body_mass[b]), model.body_inertia[b].tolist()
        body.ipos, body.iquat = model.body_ipos[b].tolist(), model.body_iquat[b].tolist()
    (root / "model.xml").write_text(spec.to_xml())
    textures = root / "assets" / "base_textures"
    textures.mkdir(parents=True)
    from PIL import Image

    Image.new("RGB", (8, 8), (84, 61, 43)).save(textures / "DarkWood2.png")


def rollouts(inputs: dict) -> dict:
    """inputs: ``arm_xml`` (our arm, for their robot dir), ``episodes``: ``[{"spec": episode JSON,
    "metadata": scene metadata, "horizon": T, "mjb": the compiled model's file}]`` and ``actions_<k>``
    (T, 8) per episode. Returns per episode ``states_<k>`` (T + 1, nq + nv), ``success_<k>`` (T,: their success
    cache after each step), ``final`` (their ``judge_success`` at the end, as the loop returns it), ``frames``
    (camera frames their renderer drew) and ``robot_qpos`` (the qpos addresses of the robot's joints)."""
    out: dict = {"final": [], "steps": [], "seconds": [], "frames": [], "robot_qpos": []}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        robot_dir = root / "robot"
        robot_dir.mkdir()
        _robot_dir(robot_dir, inputs["arm_xml"])
        for k, episode in enumerate(inputs["episodes"]):
            scene = root / f"scene_{k}.xml"
            scene.write_text("<mujoco/>")
            (root / f"scene_{k}_metadata.json").write_text(json.dumps(episode["metadata"]))
            model = mujoco.MjModel.from_binary_path(episode["mjb"])
            start, _CountingRenderer.frames = time.perf_counter(), 0
            final, success, states = _run(model, str(scene), episode, inputs[f"actions_{k}"], robot_dir)
            out["seconds"].append(round(time.perf_counter() - start, 1))
            out["frames"].append(_CountingRenderer.frames)
            out["robot_qpos"].append([int(model.jnt_qposadr[j]) for j in range(model.njnt)
                                      if model.joint(j).name.startswith("robot_0/")])
            out["final"].append(final)
            out["steps"].append(len(success))
            out[f"success_{k}"] = np.asarray(success, dtype=bool)
            out[f"states_{k}"] = np.asarray(states)
    return out


def _run(model, scene_path: str, episode: dict, actions: np.ndarray, robot_dir: Path):
    class Config(JsonBenchmarkEvalConfig):
        robot_config: FrankaRobotConfig = FrankaRobotConfig(robot_dir=robot_dir, robot_view_factory=_View)
        policy_config: BasePolicyConfig = BasePolicyConfig(policy_cls=Replay, policy_factory=Replay,
                                                           policy_type="replay")

    config = Config()
    config.task_horizon = int(episode["horizon"])
    spec = EpisodeSpec.model_validate(episode["spec"])
    sampler = object.__new__(JsonEvalTaskSampler)  # its __init__ loads the scene index; the spec is given
    sampler.episode_spec = spec
    sampler.config = config
    sampler._task_cls = None
    sampler._eval_camera_system = None
    sampler._recorded_camera_config = sampler._build_camera_config_from_spec(spec)
    config.camera_config = sampler._recorded_camera_config
    config.task_type = sampler._infer_task_type(spec)
    if config.robot_config.action_noise_config is not None:
        config.robot_config.action_noise_config.enabled = False
    env = CPUMujocoEnv(config, lambda data: config.robot_config.robot_cls(data, config), model, scene_path,
                       parallelize=False)
    sampler.randomize_scene(env, env.current_robot.robot_view)
    task = sampler._sample_task(env)
    Replay.actions = np.asarray(actions, dtype=np.float64)
    policy = Replay(config)
    task.register_policy(policy)
    final = ParallelRolloutRunner.run_single_rollout(episode_seed=0, task=task, policy=policy)
    env.cleanup_rendering()
    states = [*policy.states, _state(env.current_data)]
    success = [bool(s[0]) for s in task.success_cache[1:]]  # [0] is the reset's
    return bool(final), success, states
