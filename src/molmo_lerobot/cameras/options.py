"""The run's camera options (``camera:`` in ``conf/eval.yaml``): which camera system each
episode runs with, set up how, and the checks that stop a nonsense combination before a run.

``camera.eval=true camera.rand_level=L`` is MolmoSpaces' ``--use_eval_cameras
--camera_rand_level L``: :class:`~molmo_lerobot.cameras.franka_eval.FrankaEvalCameraSystem`
replaces every episode's recorded cameras (as ``camera.system=FrankaEvalCameraSystem`` does).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from molmo_lerobot.cameras.base import CameraSystem, choose_camera_system
from molmo_lerobot.cameras.franka_eval import FrankaEvalCameraSystem

EVAL_NAMES = (FrankaEvalCameraSystem.name, *FrankaEvalCameraSystem.aliases)


def run_camera_system(camera: Mapping[str, Any] | None) -> str | None:
    """The camera system the run's options name: ``camera.eval=true`` is the eval system,
    else ``camera.system`` (``None``: the episode's or the robot's choice)."""
    camera = camera or {}
    return FrankaEvalCameraSystem.name if camera.get("eval") else camera.get("system")


def episode_camera_system(episode: Any, camera: Mapping[str, Any] | None, resolve: Callable[[str], CameraSystem],
                          robot_default: str | None = None) -> CameraSystem:
    """The camera system ``episode`` runs with (see :func:`~molmo_lerobot.cameras.base.choose_camera_system`),
    set up by the run's ``camera`` options; ``resolve`` looks a system up by name or alias."""
    configured = run_camera_system(camera)
    replaces = resolve(configured).replaces_recorded if configured else False
    return resolve(choose_camera_system(episode, configured, robot_default, replaces)).configured(camera or {})


def camera_option_problems(camera: Any) -> list[str]:
    """Every problem of the run's ``camera`` options, one line each."""
    if camera is None:
        return []
    if not isinstance(camera, Mapping):
        return [f"camera: expected a mapping, got {camera!r}"]
    out = []
    use_eval = camera.get("eval", False)
    if not isinstance(use_eval, bool):
        out.append(f"camera.eval: expected true or false, got {use_eval!r}")
    level = camera.get("rand_level", 0)
    if not (isinstance(level, int | float) and not isinstance(level, bool) and math.isfinite(level)
            and 0 <= level <= 100):
        out.append(f"camera.rand_level: expected a number in 0-100 (MolmoSpaces' --camera_rand_level), got {level!r}")
    system = camera.get("system")
    if use_eval is True and system is not None and system not in EVAL_NAMES:
        out.append(f"camera.eval=true uses {FrankaEvalCameraSystem.name}; it conflicts with camera.system={system}")
    randomization = camera.get("randomization", 0)
    if not (isinstance(randomization, int) and not isinstance(randomization, bool) and 0 <= randomization <= 3):
        out.append(f"camera.randomization: expected a level 0-3 (0: off), got {randomization!r}")
    out.extend(_override_problems(camera.get("overrides")))
    evaluating = use_eval is True or system in EVAL_NAMES
    if level and not evaluating and not out:
        out.append("camera.rand_level applies to MolmoSpaces' eval cameras: add camera.eval=true")
    if evaluating:
        if camera.get("randomization"):
            out.append("camera.randomization jitters the episode's recorded cameras, which the eval cameras "
                       "replace: use camera.rand_level (or camera.eval=false)")
        if camera.get("overrides"):
            out.append("camera.overrides edits the episode's recorded cameras, which the eval cameras replace")
    return out


def _override_problems(overrides: Any) -> list[str]:
    """``camera.overrides``: ``{camera: {field: value}}`` with finite numbers and a field of view in (0, 180)."""
    if not overrides:
        return []
    if not isinstance(overrides, Mapping) or not all(isinstance(v, Mapping) for v in overrides.values()):
        return [f"camera.overrides: expected {{camera: {{field: value}}}}, got {overrides!r}"]
    out = []
    for name, fields in overrides.items():
        for field, value in fields.items():
            key = f"camera.overrides.{name}.{field}"
            numbers = value if isinstance(value, list | tuple) else [value]
            if any(isinstance(v, float) and not math.isfinite(v) for v in numbers):
                out.append(f"{key}: expected finite numbers, got {value!r}")
            elif field == "fov" and not (isinstance(value, int | float) and not isinstance(value, bool)
                                         and 0 < value < 180):
                out.append(f"{key}: expected a field of view in (0, 180) degrees, got {value!r}")
    return out
