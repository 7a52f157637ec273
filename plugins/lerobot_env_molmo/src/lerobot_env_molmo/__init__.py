"""``--env.type=molmo``: molmo_lerobot benchmarks inside LeRobot's own tools.

``lerobot-eval --policy.path=… --env.type=molmo --env.task=pick_v1`` (a shipped benchmark name or a
benchmark directory). Observation and action features are named as in our ``record=true`` datasets
(``observation.images.<camera>``, ``observation.state``, ``action``: the env's feature map,
:mod:`molmo_lerobot.features`), so a policy trained with
``lerobot-train`` on such a dataset evaluates here without mapping flags. ``--seed=0`` runs the
benchmark's episodes in order; ``--seed=S`` starts at episode ``S mod N`` (see
``molmo_lerobot.gym_env``). LeRobot's ``pc_success`` counts an episode as a success if any step
succeeded: that is ``extra.success_any_step`` in ``molmo-eval``'s episodes.jsonl. ``--env.environment_state=true``
adds the task's ground truth as ``observation.environment_state`` (what ``record_environment_state=true``
records and ``molmo-eval`` passes to a policy trained on it).

Rendering: with ``MUJOCO_GL`` unset the env renders through EGL (as ``molmo-eval``); if MuJoCo cannot
render at all, building the config exits with one line saying what to set (``SystemExit``), not with
LeRobot's "failed when parsing" (draccus reports any other exception of ``__post_init__`` as that).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Any

from molmo_lerobot.gl import use_headless_gl

use_headless_gl()  # before anything imports MuJoCo: unset, it would pick GLFW and need a display

from lerobot.configs.types import FeatureType, PolicyFeature  # noqa: E402
from lerobot.envs.configs import EnvConfig  # noqa: E402

from molmo_lerobot.features import ACTION, ENV_STATE, ENV_STATE_KEY, STATE, image_feature  # noqa: E402


@EnvConfig.register_subclass("molmo")
@dataclass
class MolmoEnvConfig(EnvConfig):
    task: str | None = "pick_v1"
    fps: int = 15
    #: molmo-eval's run seed: per-episode simulator seeds derive from it and each episode's content
    run_seed: int = 0
    #: policy steps per episode (default: as molmo-eval resolves it per task)
    horizon: int | None = None
    end_on_success: bool = False
    #: add ``environment_state`` (-> ``observation.environment_state``) to every observation
    environment_state: bool = False
    timing: dict[str, float] = field(default_factory=dict)
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from molmo_lerobot.gl import GLError
        from molmo_lerobot.gym_env import MolmoEnv

        try:
            env = MolmoEnv(**self.gym_kwargs)
        except GLError as exc:  # no rendering here is no config error: say what to set, not "failed when parsing"
            raise SystemExit(f"error: --env.type=molmo: {exc}") from None
        try:
            self.fps = env.metadata["render_fps"]
            fmap = env.features
        finally:
            env.close()
        self.features = {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(fmap.action_dim,)),
                         "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(fmap.state_dim,))}
        self.features_map = {ACTION: ACTION, "agent_pos": STATE}
        if fmap.env_state_names:
            self.features[ENV_STATE_KEY] = PolicyFeature(type=FeatureType.ENV, shape=(len(fmap.env_state_names),))
            self.features_map[ENV_STATE_KEY] = ENV_STATE
        for cam, shape in fmap.camera_shapes.items():
            key = f"pixels/{cam}"
            self.features[key] = PolicyFeature(type=FeatureType.VISUAL, shape=shape)
            self.features_map[key] = image_feature(cam)

    @property
    def gym_kwargs(self) -> dict[str, Any]:
        return {"benchmark": self.task, "run_seed": self.run_seed, "horizon": self.horizon,
                "end_on_success": self.end_on_success, "timing": dict(self.timing) or None,
                "environment_state": self.environment_state}

    def create_envs(self, n_envs: int, use_async_envs: bool = False) -> dict[str, dict[int, Any]]:
        """One vector env of ``n_envs`` copies (a benchmark path is no valid gym id, so no ``gym.make``)."""
        import gymnasium as gym
        from gymnasium.vector import AutoresetMode

        from molmo_lerobot.gym_env import MolmoEnv

        make_one = partial(MolmoEnv, **self.gym_kwargs)
        if use_async_envs and n_envs > 1:
            vec = gym.vector.AsyncVectorEnv([make_one] * n_envs, autoreset_mode=AutoresetMode.SAME_STEP,
                                            context="forkserver")
        else:
            vec = gym.vector.SyncVectorEnv([make_one] * n_envs, autoreset_mode=AutoresetMode.SAME_STEP)
        return {self.type: {0: vec}}
