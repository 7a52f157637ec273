"""ALOHA as an env suite: gym-aloha's bimanual tasks (``AlohaInsertion-v0``, ``AlohaTransferCube-v0``) in LeRobot's
``aloha`` convention, played in the ALOHA venv.

``lerobot-eval --env.type=aloha --env.task=<task>`` builds ``gym_aloha/<task>`` with ``obs_type=pixels_agent_pos``
and ``max_episode_steps=400`` (LeRobot's ``AlohaEnv`` config); the policy sees ``observation.images.top`` (the top
camera, 480 × 640) and ``observation.state`` (``agent_pos``: the 14 joint positions, each arm's six joints and
normalised gripper, as float32), and returns a 14-D action: the same joints' targets, absolute. A step's reward is
gym-aloha's stage (0 … 4: touched, lifted, handed over / peg and socket held, inserted); the env terminates, and
the step succeeds, at reward 4 (its ``max_reward``). An episode lasts at most LeRobot's ``episode_length``
(:data:`MAX_STEPS`) at 50 steps/s, and episode ``k`` of a run with seed ``S`` resets the env with seed ``S + k``
(``eval_policy``'s seeding with ``--eval.batch_size=1``): the seed alone places the cube, or the peg and socket.

gym-aloha's dm-control pins mujoco 3.8.1 while this project keeps MolmoSpaces' 3.5.0, so it runs in a venv of its
own (``make .aloha-venv``; ``MOLMO_ALOHA_VENV`` names another) behind :mod:`~molmo_lerobot.suites.aloha_server`,
as LIBERO does; :class:`AlohaSuite` is the worker's end.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from molmo_lerobot.allocator import child_env
from molmo_lerobot.suites.episode import TaskEpisode, plan_task_episodes, task_episode_problems
from molmo_lerobot.suites.pipe import SuiteProcess

#: our benchmark -> gym-aloha's task (``gym_aloha/<task>``, LeRobot's ``--env.task``)
TASKS = {"aloha_insertion": "AlohaInsertion-v0", "aloha_transfer_cube": "AlohaTransferCube-v0"}
#: LeRobot's ``aloha`` ``episode_length`` (the parity test checks it against LeRobot's config)
MAX_STEPS = 400
#: LeRobot's ``aloha`` ``fps`` (gym-aloha's control rate: ``DT`` 0.02 s)
CONTROL_HZ = 50
#: the top camera's frames: gym-aloha renders 480 × 640 whatever it is asked (height, width)
IMAGE_HEIGHT, IMAGE_WIDTH = 480, 640
ACTION_DIM = STATE_DIM = 14
#: the one move group a molmo-eval policy sees: both arms' 14 joint targets its command, their 14 joint positions
#: (``agent_pos``) its observed ``qpos``
MOVE_GROUP = "arms"
CAMERA = "top"
#: gym-aloha's reward at success (``max_reward`` of both tasks)
MAX_REWARD = 4
#: where ALOHA comes from (the ALOHA venv: gym-aloha ships its MJCF and meshes)
DISTRIBUTIONS = ("gym-aloha",)
_REPO = Path(__file__).resolve().parents[3]


def aloha_venv() -> Path:
    """The ALOHA venv: ``$MOLMO_ALOHA_VENV``, else ``.aloha-venv`` at the repository root."""
    return Path(os.environ.get("MOLMO_ALOHA_VENV") or _REPO / ".aloha-venv")


@dataclass(frozen=True)
class AlohaEpisode(TaskEpisode):
    """One ALOHA episode; its ``instruction`` is what ``lerobot-eval`` gives the policy as its ``task``: gym-aloha's
    (``insertion``, ``transfer_cube``)."""


def plan_episodes(suite: str, tasks: Iterable[Mapping[str, Any]], episodes_per_task: int, seed: int = 0,
                  horizon: int | None = None) -> list[AlohaEpisode]:
    """``episodes_per_task`` episodes of each task (a benchmark has one), episode ``k`` seeded ``seed + k``;
    ``horizon`` overrides LeRobot's ``episode_length``."""
    steps = MAX_STEPS if horizon is None else int(horizon)
    return plan_task_episodes(AlohaEpisode, suite, tasks, episodes_per_task, seed, steps)


def episode_problems(episode: AlohaEpisode, tasks: Iterable[Mapping[str, Any]]) -> list[str]:
    """What is wrong with ``episode`` against the catalogue: the benchmark's task, with its instruction."""
    return task_episode_problems(episode, tasks, episode.suite)


def policy_observation(obs: Mapping[str, Any], step: int) -> dict[str, Any]:
    """An ALOHA observation in our policy interface: camera ``top`` (none when the step drew no frame), the 14
    joint positions as ``qpos["arms"]``."""
    out = {"qpos": {MOVE_GROUP: obs["observation.state"]}, "prompt": obs["task"], "step": step}
    if "observation.images.top" in obs:
        out["images"] = {CAMERA: obs["observation.images.top"]}
    return out


class AlohaSuite(SuiteProcess):
    """``aloha_server`` in the ALOHA venv, behind the suite interface :class:`~molmo_lerobot.suites.benchmark.
    SuiteSession` plays (``tasks``, ``reset``, ``step``, ``close``, ``alive``)."""

    def __init__(self, venv: Path | None = None) -> None:
        venv = venv or aloha_venv()
        remedy = (f"the ALOHA venv is {venv}: run `make .aloha-venv` (it builds {_REPO / '.aloha-venv'}) or set "
                  "MOLMO_ALOHA_VENV to a venv it built")
        super().__init__(venv / "bin" / "python", "molmo_lerobot.suites.aloha_server",
                         env={"MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), **child_env()},
                         pythonpath=[_REPO / "src"], remedy=remedy)

    def tasks(self, suite: str) -> list[dict[str, Any]]:
        if suite not in TASKS:
            raise ValueError(f"unknown ALOHA benchmark {suite!r} (known: {', '.join(TASKS)})")
        return self.request("tasks", task=TASKS[suite])["tasks"]

    def reset(self, episode: AlohaEpisode) -> dict[str, np.ndarray]:
        return self.request("reset", task=episode.task, seed=episode.seed)["observation"]

    def step(self, action: np.ndarray, images: bool = True) -> dict[str, Any]:
        """One step; without ``images`` its frame is not drawn and the observation has the state only."""
        return self.request("step", action=np.asarray(action, dtype=np.float32), images=images)
