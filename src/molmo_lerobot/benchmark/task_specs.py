"""Which model an episode's task is validated with, and parsing an episode with it.

The task's plugin owns its model (``TaskType.spec_model``): the task type is found in the
plugin registry by ``task_cls`` (MolmoSpaces' dotted class paths are aliases there; a class
shared by several task types is told apart by ``task_type``), else by ``task_type``. A
MolmoSpaces task type that no plugin here provides yet (door opening, navigation) is typed
by its reference model below, so its files validate with MolmoSpaces' defaults; a plugin
providing it takes precedence. Any other task is a :class:`GenericTaskSpec`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any

from pydantic import AfterValidator, Field, Strict

from molmo_lerobot.benchmark import molmospaces
from molmo_lerobot.benchmark.schema import TASK_MODEL, BaseTaskSpec, EpisodeSpec, FiniteList, GenericTaskSpec, Pose7
from molmo_lerobot.plugins import PluginConflict, PluginError, Plugins


def _count(low: int, high: int, what: str) -> AfterValidator:
    """A list of ``low``..``high`` values, or ``None``."""
    def check(values: list[float] | None) -> list[float] | None:
        if values is not None and not low <= len(values) <= high:
            raise ValueError(f"expected {what}, got {len(values)} values")
        return values
    return AfterValidator(check)


#: a JSON number (``"0.5"`` or ``true`` is no threshold)
StrictNumber = Annotated[float, Strict()]


class DoorOpeningTaskSpec(BaseTaskSpec):
    """Open a door to at least ``door_openness_threshold`` of its joint range."""

    door_body_name: Annotated[str, Field(min_length=1)]
    articulated_joint_range: Annotated[FiniteList | None, _count(2, 2, "[closed, open]: 2 values")] = None
    #: MolmoSpaces reads the first value (the hinge's start)
    articulated_joint_reset_state: Annotated[FiniteList | None, _count(1, 1 << 20, "at least 1 value")] = None
    door_openness_threshold: StrictNumber = Field(default=0.67, ge=0, le=1)  # opening fraction


class NavToObjTaskSpec(BaseTaskSpec):
    """Navigate to within ``succ_pos_threshold`` metres of a visible candidate object."""

    pickup_obj_name: str
    pickup_obj_candidates: list[str] | None = None
    pickup_obj_start_pose: Pose7 | None = None
    receptacle_name: str | None = None
    succ_pos_threshold: StrictNumber = Field(default=1.5, ge=0)  # metres


#: MolmoSpaces task types no plugin here provides yet -> their reference spec models.
MOLMOSPACES_ONLY_SPECS: dict[str, type[BaseTaskSpec]] = {
    "door_opening": DoorOpeningTaskSpec,
    "nav_to_obj": NavToObjTaskSpec,
}


def task_spec_model(plugins: Plugins, task: Mapping[str, Any]) -> tuple[str, type[BaseTaskSpec]]:
    """``(task type name, spec model)`` for a task dict; ``("generic", GenericTaskSpec)`` when unknown.

    Raises :class:`~molmo_lerobot.plugins.PluginConflict` when several plugins provide the
    task type and the run pins none (the run must choose one).
    """
    task_cls, task_type = task.get("task_cls"), task.get("task_type")
    task_type = task_type if isinstance(task_type, str) else None
    keys = [molmospaces.task_name_for(task_cls, task_type)] if isinstance(task_cls, str) else []
    for key in [*keys, *([task_type] if task_type else [])]:
        try:
            found = plugins.task_type(key)
        except PluginConflict:
            raise
        except PluginError:
            continue
        return found.name, found.spec_model
    name = molmospaces.known_task_name(task_cls, task_type) if isinstance(task_cls, str) else None
    name = name or (molmospaces.known_task_name(task_type) if task_type else None)
    if name in MOLMOSPACES_ONLY_SPECS:
        return name, MOLMOSPACES_ONLY_SPECS[name]
    return "generic", GenericTaskSpec


def parse_episode(data: Any, plugins: Plugins) -> EpisodeSpec:
    """Validate an episode dict, its task with the model of the plugin that owns it.

    Raises ``pydantic.ValidationError`` (every problem, located by field).
    """
    return EpisodeSpec.model_validate(data, context={TASK_MODEL: lambda task: task_spec_model(plugins, task)})
