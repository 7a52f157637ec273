"""Camera systems: how an episode's cameras become MuJoCo cameras.

A :class:`CameraSystem` is what a camera plugin returns from ``molmo_camera_systems()``.
It edits the world spec before compilation; the environment then renders each named
camera at the episode's ``img_resolution``. Which system an episode uses is
:func:`choose_camera_system`'s answer.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import mujoco
import numpy as np

from molmo_lerobot.hashing import episode_digest
from molmo_lerobot.poses import Vector

STANDARD = "standard"


class CameraSystem(ABC):
    """Builds cameras into a world spec."""

    name: str
    aliases: tuple[str, ...] = ()

    @abstractmethod
    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None], episode: Any = None) -> list[str]:
        """Add the system's MuJoCo cameras and return their names in order.

        ``cameras`` are the episode's camera specs (a system may ignore them), ``episode`` the
        whole :class:`~molmo_lerobot.benchmark.schema.EpisodeSpec`. ``find_body`` resolves a
        body name (robot bodies may carry a prefix in the assembled scene) and returns
        ``None`` when no such body exists.
        """

    def episode_key(self, episode: Any) -> str:
        """What, besides the episode's scene and camera specs, makes this system's cameras differ
        between episodes ("" for deterministic systems; randomized ones return their seed)."""
        return ""

    #: whether :meth:`place` needs to run on the compiled scene
    places_in_scene: bool = False
    #: whether the system, when the run names it, also replaces episodes' own ``cameras``
    #: (MolmoSpaces' eval cameras do; other systems only serve episodes without cameras)
    replaces_recorded: bool = False

    def configured(self, options: Mapping[str, Any]) -> CameraSystem:
        """This system set up by the run's ``camera`` options (e.g. ``rand_level``); most take none."""
        return self

    def place(self, env: Any) -> dict[str, tuple[Vector, Vector, float]]:
        """Poses that depend on the compiled scene in its initial state (``env``: a reset
        :class:`~molmo_lerobot.sim.env.Env` on a scratch copy of the model): camera name ->
        (position, wxyz quaternion in its parent body's frame, fovy). Called once per built
        model when :attr:`places_in_scene`; the returned poses are written into the model."""
        return {}


def choose_camera_system(episode: Any, configured: str | None, robot_default: str | None = None,
                         replaces_recorded: bool = False) -> str:
    """The camera system an episode runs with: ``standard`` for the episode's own ``cameras``
    (unless the run's system ``replaces_recorded``), else the run's ``camera.system``, else
    ``source.camera_system_class``, else the robot's default (``franka_droid``:
    ``FrankaDroidCameraSystem``), else ``standard`` (no cameras)."""
    if episode.cameras and not (configured and replaces_recorded):
        return STANDARD
    source = getattr(episode, "source", None)
    return configured or getattr(source, "camera_system_class", None) or robot_default or STANDARD


def episode_rng(episode: Any, stream: int = 0) -> np.random.Generator:
    """A generator seeded by the episode's content (its JSON): the same episode, the same draws;
    ``stream`` picks an independent sequence for another use."""
    digest = episode_digest(episode)
    return np.random.default_rng([*digest[:16], stream] if stream else list(digest[:16]))

