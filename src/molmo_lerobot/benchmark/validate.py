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
from typing import Any

from molmo_lerobot.benchmark import molmospaces
from molmo_lerobot.benchmark.load import Benchmark, Problem
from molmo_lerobot.benchmark.schema import EpisodeSpec
from molmo_lerobot.features import image_feature
from molmo_lerobot.plugins import PluginConflict, PluginError, Plugins
from molmo_lerobot.sim.scenes import SceneContext, SceneDataset


def validate_benchmark(bench: Benchmark, plugins: Plugins, scenes: SceneContext) -> list[Problem]:
    """All problems of all episodes of ``bench``, in episode order (empty when it can run)."""
    problems: list[Problem] = []
    for index, episode in enumerate(bench.episodes):
        file = bench.origins[index].file if index < len(bench.origins) else str(bench.path)
        problems.extend(validate_episode(episode, plugins, scenes, index=index, file=file))
    return problems


def validate_episode(episode: EpisodeSpec, plugins: Plugins, scenes: SceneContext, *, index: int | None = None,
                     file: str = "<episode>") -> list[Problem]:
    """Problems of one episode (``scenes``: where the run's scene data lives); ``index``/``file`` only label them."""
    out: list[Problem] = []

    def problem(field: str, message: str) -> None:
        out.append(Problem(file, message, index, field))

    def warning(field: str, message: str) -> None:
        out.append(Problem(file, message, index, field, warning=True))

    task_report = warning if molmospaces.known_task_name(episode.task.task_cls, episode.task.task_type) else problem
    task_type = _lookup(plugins, "task_type", episode.task_name,
                        "task.task_type" if _by_type(episode) else "task.task_cls", task_report)
    contradiction = _task_type_contradiction(episode, plugins, task_type)
    if contradiction:
        problem("task.task_type", contradiction)

    robot = _lookup(plugins, "robot", episode.robot.robot_name, "robot.robot_name", warning, "robot",
                    "install a robot plugin that provides it")
    if robot is not None:
        for group, values in episode.robot.init_qpos.items():
            field = f"robot.init_qpos.{group}"
            if group not in robot.move_groups:
                if values:  # MolmoSpaces writes empty lists for groups a robot lacks ("base": [])
                    warning(field, f"robot {robot.name!r} has no move group {group!r} "
                                   f"(move groups: {', '.join(robot.move_groups)})")
                continue
            try:
                robot.init_qpos(group, values)
            except ValueError as exc:
                warning(field, str(exc))

    robot_extra = episode.robot.model_extra or {}
    if "base_size" in robot_extra:
        from molmo_lerobot.robots.base import parse_base_size

        try:
            parse_base_size(robot_extra["base_size"])
        except ValueError as exc:
            problem("robot.base_size", str(exc))

    scene = _lookup(plugins, "scene_dataset", episode.scene_dataset, "scene_dataset", problem, "scene dataset")
    reason = scene.missing(episode, scenes) if scene is not None else None
    if reason:
        warning("scene_dataset", reason)

    if not episode.cameras:  # a camera system places them: camera.system=, source.camera_system_class, the robot's
        from molmo_lerobot.cameras.base import STANDARD, choose_camera_system

        system = choose_camera_system(episode, None, robot.default_camera_system if robot is not None else None)
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
    if task_type is not None and not contradiction:
        def metadata() -> Any:
            return _scene_metadata(scene, episode) if scene is not None and not reason else None

        for p in task_type.spec_problems(episode, metadata):
            (warning if p.warning else problem)(p.field, p.message)
    return out


def _task_type_contradiction(episode: EpisodeSpec, plugins: Plugins, task_type: Any) -> str | None:
    """Why ``task.task_type`` contradicts ``task.task_cls`` (another task type, or not one the shared
    class has), or ``None``; a ``task_type`` no plugin knows (MolmoSpaces' own names) is left alone."""
    cls, given = episode.task.task_cls, episode.task.task_type
    if not given or task_type is None:
        return None
    shared = molmospaces.SHARED_TASK_CLS.get(cls)
    if shared is not None:
        return None if given in shared else (f"{given!r} is not a task type of task_cls {cls!r} "
                                             f"(one of {', '.join(shared)})")
    try:
        named = plugins.task_type(given)
    except PluginConflict:
        raise
    except PluginError:
        return None
    if named.name != task_type.name:
        return (f"{given!r} contradicts task_cls {cls!r}, which is task type {task_type.name!r}; "
                "fix one of them")
    return None


def _scene_metadata(scene: SceneDataset, episode: EpisodeSpec) -> Any:
    """The episode's house metadata where its scene dataset gives it cheaply, else ``None``."""
    try:
        return scene.metadata(episode.house_index)
    except Exception:  # data not installed here, a house out of range: the preflight reports those
        return None


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
