"""PushT as an env suite: ``gym_pusht``'s env (the registry's ``gym-pusht``) in LeRobot's ``pusht`` convention.

``lerobot-eval --env.type=pusht`` builds ``gym_pusht/PushT-v0`` with pixels and the agent's position
(``obs_type=pixels_agent_pos``); the policy sees ``observation.image`` (gym_pusht's 96² rendering, which LeRobot's
config leaves at its default) and ``observation.state`` (the agent's 2-D position, as float32), and returns a
2-D action: the agent's target position in gym_pusht's 512 × 512 workspace (no clipping). A step's reward is
gym_pusht's coverage of the goal over its success threshold, clipped to 1; the env terminates, and the step
succeeds, when the coverage exceeds that threshold (0.95). Episodes last at most LeRobot's ``episode_length``
(:data:`MAX_STEPS`) at 10 steps/s, and episode ``k`` of a run with seed ``S`` resets the env with seed ``S + k``
(``eval_policy``'s seeding with ``--eval.batch_size=1``): the seed alone places the agent and the block.

Unlike LIBERO, gym_pusht shares the main venv (pymunk, pygame, shapely; its own ``opencv-python`` requirement is
left out because the venv's ``opencv-python-headless`` provides ``cv2``), so :class:`PushTSuite` holds the env in
the worker's own process.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from molmo_lerobot.suites.episode import TaskEpisode, plan_task_episodes, task_episode_problems

#: gym_pusht's env id as LeRobot's ``pusht`` config names it (``gym_<type>/<task>``)
ENV_ID = "gym_pusht/PushT-v0"
TASK = "PushT-v0"
#: LeRobot's ``pusht`` ``episode_length`` (the parity test checks it against LeRobot's config)
MAX_STEPS = 300
#: LeRobot's ``pusht`` ``fps`` (gym_pusht's control rate)
CONTROL_HZ = 10
#: the observed image's side: gym_pusht's default, which LeRobot's ``pusht`` config does not override
IMAGE_SIZE = 96
ACTION_DIM = 2
#: gym_pusht's workspace: an action is a target position in [0, 512]²
WORKSPACE = (0.0, 512.0)
#: the one move group a molmo-eval policy sees: the agent's 2-D target position is its command, the agent's
#: position its observed ``qpos``
MOVE_GROUP = "agent"
CAMERA = "image"
#: where PushT comes from (its env draws the scene itself: no asset files)
DISTRIBUTIONS = ("gym-pusht",)
#: LeRobot's ``pusht`` env kwargs besides the observation size (``PushtEnv.gym_kwargs``)
_GYM_KWARGS: dict[str, Any] = {"obs_type": "pixels_agent_pos", "render_mode": "rgb_array", "visualization_width": 384,
               "visualization_height": 384}


@dataclass(frozen=True)
class PushTEpisode(TaskEpisode):
    """One PushT episode; its ``instruction`` is empty (``lerobot-eval`` gives PushT policies an empty ``task``)."""


def plan_episodes(suite: str, tasks: Iterable[Mapping[str, Any]], episodes_per_task: int, seed: int = 0,
                  horizon: int | None = None) -> list[PushTEpisode]:
    """``episodes_per_task`` episodes of each task (PushT has one), episode ``k`` seeded ``seed + k``;
    ``horizon`` overrides LeRobot's ``episode_length``."""
    steps = MAX_STEPS if horizon is None else int(horizon)
    return plan_task_episodes(PushTEpisode, suite, tasks, episodes_per_task, seed, steps)


def episode_problems(episode: PushTEpisode, tasks: Iterable[Mapping[str, Any]]) -> list[str]:
    """What is wrong with ``episode`` against the catalogue: a task PushT has, with its (empty) instruction."""
    return task_episode_problems(episode, tasks, "PushT")


def policy_observation(obs: Mapping[str, Any], step: int) -> dict[str, Any]:
    """A PushT observation in our policy interface: camera ``image``, the agent's position as ``qpos["agent"]``."""
    return {"images": {CAMERA: obs["observation.image"]}, "qpos": {MOVE_GROUP: obs["observation.state"]},
            "prompt": obs["task"], "step": step}


class PushTSuite:
    """gym_pusht's env in this process, behind the suite interface :class:`~molmo_lerobot.suites.benchmark.
    SuiteSession` plays (``tasks``, ``reset``, ``step``, ``close``, ``alive``)."""

    #: in the worker's own process: never lost on its own
    alive = True

    def __init__(self, image_size: int = IMAGE_SIZE) -> None:
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")  # pygame's import banner
        with warnings.catch_warnings():  # gym.make imports gym_pusht's env module, which imports pygame
            warnings.filterwarnings("ignore", "pkg_resources is deprecated", UserWarning)  # pygame's own import
            import gym_pusht  # noqa: F401  (registers gym_pusht/PushT-v0)
            import gymnasium as gym

            self.env = gym.make(ENV_ID, disable_env_checker=True, observation_width=image_size,
                                observation_height=image_size, **_GYM_KWARGS)
        self.image_size = image_size

    def tasks(self, suite: str) -> list[dict[str, Any]]:
        return [{"task_id": 0, "task": TASK, "instruction": ""}]

    def reset(self, episode: PushTEpisode) -> dict[str, np.ndarray]:
        obs, _info = self.env.reset(seed=episode.seed)
        return self._observation(obs)

    def step(self, action: np.ndarray, images: bool = True) -> dict[str, Any]:
        """One step with a 2-D target position, as float32 (what a LeRobot policy's tensor gives the env).
        gym_pusht draws its frame inside every step (a cheap 96² pygame canvas), ``images`` or not."""
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (ACTION_DIM,):
            raise ValueError(f"PushT: an action is a 2-D target position, got shape {action.shape}")
        obs, reward, terminated, _truncated, info = self.env.step(action)
        return {"observation": self._observation(obs), "reward": float(reward), "terminated": bool(terminated),
                "success": bool(info["is_success"])}

    def close(self) -> None:
        self.env.close()

    @staticmethod
    def _observation(obs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"observation.image": obs["pixels"], "observation.state": obs["agent_pos"].astype(np.float32)}
