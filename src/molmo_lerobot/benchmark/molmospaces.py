"""MolmoSpaces names, so that benchmark files written for MolmoSpaces resolve unchanged.

MolmoSpaces identifies a task by the dotted path of its task class (``task_cls``). Files
from before its package rename use the ``mujoco_thor.`` prefix instead of
``molmo_spaces.``; both spellings are accepted. Open and close share one class and are
told apart by ``task_type``.
"""

from __future__ import annotations

#: Current and legacy package prefixes of MolmoSpaces task classes.
PACKAGE_PREFIXES = ("molmo_spaces.", "mujoco_thor.")

_OPENING = "tasks.opening_tasks.OpeningTask"

#: Our task type name -> MolmoSpaces task class path (without the package prefix).
_TASK_CLASS_PATHS: dict[str, str] = {
    "pick": "tasks.pick_task.PickTask",
    "pick_and_place": "tasks.pick_and_place_task.PickAndPlaceTask",
    "pick_and_place_next_to": "tasks.pick_and_place_next_to_task.PickAndPlaceNextToTask",
    "pick_and_place_color": "tasks.pick_and_place_color_task.PickAndPlaceColorTask",
    "open": _OPENING,
    "close": _OPENING,
    "door_opening": "tasks.opening_tasks.DoorOpeningTask",
    "nav_to_obj": "tasks.nav_task.NavToObjTask",
}

#: Task type name -> every dotted ``task_cls`` spelling MolmoSpaces files use for it.
TASK_CLS: dict[str, tuple[str, ...]] = {
    name: tuple(prefix + path for prefix in PACKAGE_PREFIXES) for name, path in _TASK_CLASS_PATHS.items()
}

#: Dotted paths of classes shared by several task types; ``task_type`` picks among them.
SHARED_TASK_CLS: dict[str, tuple[str, ...]] = {
    prefix + _OPENING: ("open", "close") for prefix in PACKAGE_PREFIXES
}

#: The task type used for a shared class when an episode gives no ``task_type``.
SHARED_TASK_DEFAULT = {cls: names[0] for cls, names in SHARED_TASK_CLS.items()}

def task_aliases(task_name: str) -> tuple[str, ...]:
    """Dotted ``task_cls`` paths a task plugin named ``task_name`` should register as aliases.

    Shared classes (``OpeningTask``) are aliases of the first task type only (``open``);
    ``close`` is reached through :func:`task_name_for`.
    """
    paths = TASK_CLS.get(task_name, ())
    return tuple(p for p in paths if SHARED_TASK_DEFAULT.get(p, task_name) == task_name)


def task_name_for(task_cls: str, task_type: str | None = None) -> str:
    """The task registry key for an episode: ``task_type`` for shared classes, else ``task_cls``."""
    if task_cls in SHARED_TASK_CLS:
        if task_type in SHARED_TASK_CLS[task_cls]:
            return task_type
        return SHARED_TASK_DEFAULT[task_cls]
    return task_cls


def known_task_name(task_cls: str, task_type: str | None = None) -> str | None:
    """Our task type name for a MolmoSpaces ``task_cls`` (or a bare task type name), else ``None``."""
    if task_cls in SHARED_TASK_CLS:
        return task_name_for(task_cls, task_type)
    if task_cls in TASK_CLS:
        return task_cls
    for name, paths in TASK_CLS.items():
        if task_cls in paths:
            return name
    return None
