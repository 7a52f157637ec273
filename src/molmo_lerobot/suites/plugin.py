"""Built-in plugin: LeRobot's env suites as benchmark kinds (``libero``: ``benchmark=libero_object`` and the other
LIBERO suites; ``pusht``: ``benchmark=pusht``; ``aloha``: ``benchmark=aloha_insertion``, ``aloha_transfer_cube``;
``metaworld``: ``benchmark=metaworld_<group>``, ``metaworld_mt50``, ``metaworld_<task>``), each with its typed
options and defaults, stated here once."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import Field

from molmo_lerobot import hookimpl
from molmo_lerobot.suites import aloha, libero, metaworld, pusht
from molmo_lerobot.suites.aloha_dataset import ROBOT_TYPE as ALOHA_ROBOT
from molmo_lerobot.suites.aloha_dataset import aloha_layout
from molmo_lerobot.suites.benchmark import EnvSuiteKind, ImageSize, SuiteKind, SuiteOptions
from molmo_lerobot.suites.episode import task_label
from molmo_lerobot.suites.libero_dataset import ROBOT_TYPE as LIBERO_ROBOT
from molmo_lerobot.suites.libero_dataset import libero_layout
from molmo_lerobot.suites.metaworld_dataset import ROBOT_TYPE as METAWORLD_ROBOT
from molmo_lerobot.suites.metaworld_dataset import metaworld_layout
from molmo_lerobot.suites.pusht_dataset import pusht_layout


class LiberoOptions(SuiteOptions):
    """LIBERO's options: LeRobot's ``LiberoEnv`` defaults."""

    image_size: ImageSize = libero.IMAGE_SIZE
    #: rebuild the scene per episode (LeRobot's default)
    hard_reset: bool = True


class PushTOptions(SuiteOptions):
    """PushT's options: gym_pusht's 96² image; ``lerobot-eval``'s 50 episodes."""

    episodes_per_task: int = Field(50, ge=1)
    image_size: ImageSize = pusht.IMAGE_SIZE


class AlohaOptions(SuiteOptions):
    """ALOHA's options: ``lerobot-eval``'s 50 episodes; gym-aloha's frames are 480 × 640, no option."""

    episodes_per_task: int = Field(50, ge=1)


class MetaWorldOptions(SuiteOptions):
    """MetaWorld's options: ``lerobot-eval``'s 50 episodes per task, LeRobot's 480² frames."""

    episodes_per_task: int = Field(50, ge=1)
    image_size: ImageSize = metaworld.IMAGE_SIZE


def _open_metaworld(options: MetaWorldOptions) -> metaworld.MetaWorldSuite:
    return metaworld.MetaWorldSuite(image_size=options.image_size)


def _open_libero(options: LiberoOptions) -> libero.LiberoSuite:
    return libero.LiberoSuite(image_size=options.image_size, hard_reset=options.hard_reset)


def _open_pusht(options: PushTOptions) -> pusht.PushTSuite:
    return pusht.PushTSuite(image_size=options.image_size)


def _libero_label(episode: libero.LiberoEpisode) -> str:
    return f"{episode.suite}/task_{episode.task_id:02d}"


def _site_packages(venv: Path) -> list[str]:
    """The site-packages directories of a suite's own venv."""
    return [str(p) for p in venv.glob("lib/python*/site-packages")]


def _open_aloha(options: AlohaOptions) -> aloha.AlohaSuite:
    return aloha.AlohaSuite()


LIBERO: SuiteKind[LiberoOptions] = SuiteKind(
    name="libero", episode=libero.LiberoEpisode, plan=libero.plan_episodes, open=_open_libero,
    task_label=_libero_label, observation=libero.policy_observation, move_group=libero.MOVE_GROUP,
    action_dim=libero.ACTION_DIM, control_hz=libero.CONTROL_HZ,
    cameras={"image": "observation.images.image", "image2": "observation.images.image2"},
    frame_size=lambda o: o.image_size, options=LiberoOptions,
    action_extra={"delta_groups": [libero.MOVE_GROUP]}, benchmarks=dict(libero.MAX_STEPS),
    check_episode=libero.episode_problems, distributions=libero.DISTRIBUTIONS,
    site_packages=lambda: _site_packages(libero.libero_venv()),
    recording=lambda o: libero_layout(o.image_size), robot=LIBERO_ROBOT, install_problem=libero.install_problem,
    remedy="make .libero-venv")

PUSHT: SuiteKind[PushTOptions] = SuiteKind(
    name="pusht", episode=pusht.PushTEpisode, plan=pusht.plan_episodes, open=_open_pusht,
    task_label=task_label, observation=pusht.policy_observation, move_group=pusht.MOVE_GROUP,
    action_dim=pusht.ACTION_DIM, control_hz=pusht.CONTROL_HZ, cameras={pusht.CAMERA: "observation.image"},
    frame_size=lambda o: o.image_size, options=PushTOptions,
    action_extra={"action_bounds": {pusht.MOVE_GROUP: pusht.WORKSPACE}},
    benchmarks={"pusht": pusht.MAX_STEPS}, check_episode=pusht.episode_problems, distributions=pusht.DISTRIBUTIONS,
    recording=lambda o: pusht_layout(o.image_size))

ALOHA: SuiteKind[AlohaOptions] = SuiteKind(
    name="aloha", episode=aloha.AlohaEpisode, plan=aloha.plan_episodes, open=_open_aloha,
    task_label=task_label, observation=aloha.policy_observation, move_group=aloha.MOVE_GROUP,
    action_dim=aloha.ACTION_DIM, control_hz=aloha.CONTROL_HZ, cameras={aloha.CAMERA: "observation.images.top"},
    frame_size=lambda o: (aloha.IMAGE_HEIGHT, aloha.IMAGE_WIDTH), options=AlohaOptions, action_extra={},
    benchmarks=dict.fromkeys(aloha.TASKS, aloha.MAX_STEPS), check_episode=aloha.episode_problems,
    distributions=aloha.DISTRIBUTIONS, site_packages=lambda: _site_packages(aloha.aloha_venv()),
    recording=lambda o: aloha_layout(),
    robot=ALOHA_ROBOT, remedy="make .aloha-venv")

METAWORLD: SuiteKind[MetaWorldOptions] = SuiteKind(
    name="metaworld", episode=metaworld.MetaWorldEpisode, plan=metaworld.plan_episodes, open=_open_metaworld,
    task_label=metaworld.task_label, observation=metaworld.policy_observation, move_group=metaworld.MOVE_GROUP,
    action_dim=metaworld.ACTION_DIM, control_hz=metaworld.CONTROL_HZ, cameras={metaworld.CAMERA: "observation.image"},
    frame_size=lambda o: o.image_size, options=MetaWorldOptions,
    action_extra={"action_bounds": {metaworld.MOVE_GROUP: metaworld.ACTION_BOUNDS}},
    benchmarks=metaworld.benchmarks(), check_episode=metaworld.episode_problems,
    distributions=metaworld.DISTRIBUTIONS, recording=lambda o: metaworld_layout(o.image_size), robot=METAWORLD_ROBOT)


@hookimpl
def molmo_benchmark_kinds() -> list[EnvSuiteKind[Any]]:
    return [EnvSuiteKind(LIBERO), EnvSuiteKind(PUSHT), EnvSuiteKind(ALOHA), EnvSuiteKind(METAWORLD)]
