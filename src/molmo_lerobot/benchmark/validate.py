"""Check a schema-valid benchmark against the installed plugins (what a run would need).

Every episode is checked and every problem returned (never raised), each naming the file,
the episode index and the field: unknown task classes (with "did you mean"), robots no
plugin provides, init_qpos that does not fit the robot's move groups, unknown scene
datasets, duplicate cameras (or names recorded as one dataset feature), empty instructions.

A file MolmoSpaces loads is valid here: what only stops it from *running here* is a
``warning`` problem (a robot, task type or camera system no installed plugin provides,
``init_qpos`` that does not fit our robot, scene assets not installed), each saying how to
get it. ``cameras: []`` means the run's camera system (``camera.system``) or the episode's
``source.camera_system_class``.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from molmo_lerobot.benchmark import molmospaces
from molmo_lerobot.benchmark.load import Benchmark, Problem
from molmo_lerobot.benchmark.schema import EpisodeSpec
from molmo_lerobot.export.frames import image_feature
from molmo_lerobot.plugins import PluginConflict, PluginError, Plugins


def validate_benchmark(bench: Benchmark, plugins: Plugins) -> list[Problem]:
    """All problems of all episodes of ``bench``, in episode order (empty when it can run)."""
    problems: list[Problem] = []
    for index, episode in enumerate(bench.episodes):
        file = bench.origins[index].file if index < len(bench.origins) else str(bench.path)
        problems.extend(validate_episode(episode, plugins, index=index, file=file))
    return problems


def validate_episode(episode: EpisodeSpec, plugins: Plugins, *, index: int | None = None, file: str = "<episode>") -> list[Problem]:
    """Problems of one episode; ``index``/``file`` only label them."""
    out: list[Problem] = []

    def problem(field: str, message: str) -> None:
        out.append(Problem(file, message, index, field))

    def warning(field: str, message: str) -> None:
        out.append(Problem(file, message, index, field, warning=True))

    task_report = warning if molmospaces.known_task_name(episode.task.task_cls, episode.task.task_type) else problem
    _lookup(plugins, "task_type", episode.task_name, "task.task_type" if _by_type(episode) else "task.task_cls",
            task_report)

    robot = _lookup(plugins, "robot", episode.robot.robot_name, "robot.robot_name", warning, "robot",
                    "install a robot plugin that provides it")
    sizes = getattr(robot, "move_groups", None)
    if isinstance(sizes, Mapping):
        for group, values in episode.robot.init_qpos.items():
            field = f"robot.init_qpos.{group}"
            if group not in sizes:
                if values:  # MolmoSpaces writes empty lists for groups a robot lacks ("base": [])
                    warning(field, f"robot {robot.name!r} has no move group {group!r} "
                                   f"(move groups: {', '.join(sizes)})")
            elif hasattr(robot, "init_qpos"):
                try:
                    robot.init_qpos(group, values)
                except ValueError as exc:
                    warning(field, str(exc))
            elif len(values) != sizes[group]:
                warning(field, f"expected {sizes[group]} values, got {len(values)}")

    if "base_size" in (episode.robot.model_extra or {}):
        from molmo_lerobot.robots.base import parse_base_size

        try:
            parse_base_size(episode.robot.model_extra["base_size"])
        except ValueError as exc:
            problem("robot.base_size", str(exc))

    scene = _lookup(plugins, "scene_dataset", episode.scene_dataset, "scene_dataset", problem, "scene dataset")
    missing = getattr(scene, "missing", None)
    reason = missing(episode) if missing is not None else None
    if reason:
        warning("scene_dataset", reason)

    if not episode.cameras:  # a camera system places them: camera.system=, source.camera_system_class, the robot's
        from molmo_lerobot.cameras.base import STANDARD, choose_camera_system

        system = choose_camera_system(episode, None, getattr(robot, "default_camera_system", None))
        if system == STANDARD:
            warning("cameras", "no cameras: the run's camera system (camera.system=...) places them")
        else:
            _lookup(plugins, "camera_system", system, "source.camera_system_class", warning, "camera system",
                    "install a plugin that provides it, or set camera.system= for the run")
    seen: dict[str, int] = {}  # dataset feature -> first camera recorded as it
    for i, cam in enumerate(episode.cameras):
        feature = image_feature(cam.name)
        if feature in seen:
            other = episode.cameras[seen[feature]].name
            problem(f"cameras[{i}].name", f"duplicate camera name {cam.name!r} (also cameras[{seen[feature]}])"
                    if other == cam.name else f"cameras {other!r} (cameras[{seen[feature]}]) and {cam.name!r} "
                    f"would both be recorded as {feature!r}; rename one")
        seen.setdefault(feature, i)
        if not 0 < cam.fov < 180:
            problem(f"cameras[{i}].fov", f"field of view must be in (0, 180) degrees, got {cam.fov}")

    if not episode.language.task_description.strip():
        problem("language.task_description", "empty task description")
    return out


def _by_type(episode: EpisodeSpec) -> bool:
    """Whether the registry key came from ``task_type`` (a class shared by several task types)."""
    return episode.task_name != episode.task.task_cls


def _lookup(plugins: Plugins, kind: str, name: str, field: str, problem: Any, what: str | None = None,
            hint: str | None = None) -> Any:
    """The ``kind`` plugin object called ``name``, or record why not as a problem on ``field``.

    The message is the registry's first line ("unknown task 'x'; did you mean ...",
    reworded as "no <what> plugin provides 'x'" when ``what`` is given), plus the error of
    any broken plugin whose entry-point name matches ``name``.
    """
    try:
        return getattr(plugins, kind)(name)
    except PluginConflict:
        raise  # two plugins provide the name: not an episode's problem, the run must pin one
    except PluginError as exc:
        text = str(exc).splitlines()[0]
        if what is not None:
            text = re.sub(r"^unknown \w+ ", f"no {what} plugin provides ", text)
        if hint:
            text += f"; {hint}"
        for rec in plugins.broken():
            if rec.name in name or name in rec.name:
                text += f"; plugin {rec.name!r} from {rec.distribution} failed to load: {rec.error}"
        problem(field, text)
        return None
