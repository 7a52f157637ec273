"""Resolve an episode's plugins (scene dataset, robot, camera system) once and build its Env.

``sim/`` never looks plugins up; this is the one place that does it for an episode.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from molmo_lerobot.cameras.options import episode_camera_system
from molmo_lerobot.sim.env import Env, Timing, make_env

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.plugins import Plugins


def build_env(spec: EpisodeSpec, timing: Timing, plugins: Plugins, camera: Mapping[str, Any] | None = None) -> Env:
    """The episode's environment; ``camera`` is the run's ``camera`` options (see
    :func:`~molmo_lerobot.cameras.options.episode_camera_system` for the choice of cameras)."""
    robot = plugins.robot(spec.robot.robot_name)
    cameras = episode_camera_system(spec, camera, plugins.camera_system, robot.default_camera_system)
    return make_env(spec, timing, plugins.scene_dataset(spec.scene_dataset), robot, cameras)
