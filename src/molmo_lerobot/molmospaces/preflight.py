"""Before any worker starts: can every episode of this run simulate here?

:func:`preflight` checks, under the run's context (its plugins, MolmoSpaces settings and asset
catalog), each episode's task type, robot, scene dataset (and its scene file and added objects),
and camera system (for ``cameras: []``), and, once per scene dataset, the installed files it reads
in place (``SceneDataset.install_problem``: the LIBERO asset distributions). It returns one
line naming what is missing, where it looked and how to get it — or ``None`` when the run can go
ahead. It changes nothing but the assets dir (scenes installed on demand are fetched).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from molmo_lerobot.context import RunContext


def _missing(spec: Any, run: RunContext, camera_system: str | None) -> tuple[str, str] | None:
    """(field, what is missing and how to get it) for the first thing ``spec`` lacks here, or ``None``."""
    from molmo_lerobot.plugins import PluginError

    plugins = run.plugins

    checks = (("task type", "task_type", spec.task_name, "task.task_cls"),
              ("robot", "robot", spec.robot.robot_name, "robot.robot_name"),
              ("scene dataset", "scene_dataset", spec.scene_dataset, "scene_dataset"))
    found = {}
    for what, kind, name, field in checks:
        try:
            found[kind] = getattr(plugins, kind)(name)
        except PluginError as exc:
            return field, f"{what} {name!r}: {str(exc).splitlines()[0]} (install a plugin that provides it)"
    scene = found["scene_dataset"]
    if hasattr(scene, "fetch"):
        scene.fetch(spec, run)  # scenes installed on demand arrive now, before any worker starts
    reason = scene.missing(spec, run)
    if reason:
        return ("house_index" if "scene_xml_paths" in reason else "scene_dataset"), reason
    from molmo_lerobot.molmospaces.scenes import MolmoSpacesScenes, resolve_object_file

    if isinstance(scene, MolmoSpacesScenes) and spec.scene_modifications.added_objects:
        for name, rel in spec.scene_modifications.added_objects.items():
            field = f"scene_modifications.added_objects[{name!r}]"
            try:
                resolve_object_file(rel, field, run)
            except FileNotFoundError as exc:
                return field, str(exc).removeprefix(f"{field}: ")
    if not spec.cameras:
        from molmo_lerobot.cameras.base import STANDARD, choose_camera_system

        system = choose_camera_system(spec, camera_system, found["robot"].default_camera_system)
        if system == STANDARD:
            return "cameras", "cameras: [] and no camera system: set camera.system= or source.camera_system_class"
        try:
            plugins.camera_system(system)
        except PluginError as exc:
            return "cameras", f"cameras: [] needs camera system {system!r}: {str(exc).splitlines()[0]}"
    return None


def _install_problem(bench: Any, run: RunContext, indices: list[int]) -> str | None:
    """A fault of the installed files a scene dataset of these episodes reads in place (its
    ``install_problem``, once per dataset), or ``None``."""
    from molmo_lerobot.plugins import PluginError

    names = dict.fromkeys(bench.episodes[i].scene_dataset for i in indices)
    for name in names:
        try:
            scene = run.plugins.scene_dataset(name)
        except PluginError:
            continue  # reported per episode below
        problem = scene.install_problem()
        if problem:
            return f"cannot simulate scene dataset {name!r}: {problem}"
    return None


def preflight(bench: Any, run: RunContext, indices: Iterable[int], skip: Iterable[int] = ()) -> str | None:
    """One line saying why the run cannot simulate (and how to fix it), or ``None``.

    ``skip`` are episodes already failed as invalid (they are reported per episode instead).
    """
    camera_system = run.config.camera.system
    skipped = set(skip)
    broken = _install_problem(bench, run, [i for i in indices if i not in skipped])
    if broken:
        return broken
    reasons: dict[tuple[str, str, str], list[int]] = {}
    for i in indices:
        if i in skipped:
            continue
        found = _missing(bench.episodes[i], run, camera_system)
        if found:
            file = bench.origins[i].file if i < len(bench.origins) else str(bench.path)
            reasons.setdefault((file, *found), []).append(i)
    if not reasons:
        return None
    ((file, field, message), eps), *rest = reasons.items()
    shown = ", ".join(map(str, eps[:5])) + (", ..." if len(eps) > 5 else "")
    n_eps = sum(len(v) for v in reasons.values())
    more = (f"; {len(rest)} more missing resource{'s' * (len(rest) != 1)} (molmo-bench validate lists them)"
            if rest else "")
    return (f"cannot simulate {n_eps} of {len(bench.episodes)} episodes: {file}: episode{'s' * (len(eps) != 1)} "
            f"{shown}: field {field}: {message}{more}")
