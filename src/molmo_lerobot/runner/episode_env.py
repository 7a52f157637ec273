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
    from molmo_lerobot.context import RunContext


def build_env(spec: EpisodeSpec, timing: Timing, run: RunContext, camera: Mapping[str, Any] | None = None) -> Env:
    """The episode's environment under the run ``run`` (its render profile); ``camera`` is the run's ``camera``
    options (see :func:`~molmo_lerobot.cameras.options.episode_camera_system` for the choice of cameras)."""
    plugins = run.plugins
    robot = plugins.robot(spec.robot.robot_name).configured(run.settings)
    cameras = episode_camera_system(spec, camera, plugins.camera_system, robot.default_camera_system)
    scene = plugins.scene_dataset(spec.scene_dataset)
    env = make_env(spec, timing, scene, robot, cameras, run, run.render_profile)
    env.task_rules = run.config.task_rules
    return env
