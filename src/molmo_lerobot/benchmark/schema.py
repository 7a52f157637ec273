"""Pydantic models of a benchmark episode, following MolmoSpaces' JSON benchmark schema.

A MolmoSpaces benchmark file validates here unchanged: field names, types and defaults
match theirs, and every model keeps unknown fields (``extra="allow"``). Poses are
``[x, y, z, qw, qx, qy, qz]``; vectors have fixed lengths and must be finite.

``EpisodeSpec.task`` is a typed task spec chosen from ``task_cls`` (``task_type`` tells
open from close, which share one class, and types a task whose class is not known here).
A task known by neither parses as :class:`GenericTaskSpec`, so that validation against the
installed task plugins, not parsing, reports it (with a "did you mean").
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Annotated, Any, Literal, Union

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Strict,
    Tag,
)
from pydantic_core import PydanticCustomError

from molmo_lerobot.benchmark import molmospaces


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow")


# Vectors ---------------------------------------------------------------------------------


def _fixed_vector(n: int, quat_at: int | None = None) -> Any:
    """A ``list[float]`` of exactly ``n`` finite values (with a non-zero quaternion at ``quat_at``)."""

    def check(v: list[float]) -> list[float]:
        if len(v) != n:
            raise PydanticCustomError("vector_length", "expected {n} values, got {got}", {"n": n, "got": len(v)})
        if not all(math.isfinite(x) for x in v):
            raise PydanticCustomError("vector_finite", "values must be finite, got {v}", {"v": v})
        if quat_at is not None and sum(x * x for x in v[quat_at : quat_at + 4]) < 1e-12:
            raise PydanticCustomError("zero_quaternion", "quaternion (qw, qx, qy, qz) must not be all zero", {})
        return v

    return Annotated[list[float], AfterValidator(check)]


def _finite_list(v: list[float]) -> list[float]:
    if not all(math.isfinite(x) for x in v):
        raise PydanticCustomError("vector_finite", "values must be finite, got {v}", {"v": v})
    return v


#: Largest image side in pixels (an 8K frame); larger asks the renderer for absurd buffers.
MAX_IMG_SIDE = 8192
#: Longest ``task_horizon_sec`` an episode may ask for (one hour of simulated time).
MAX_TASK_HORIZON_SEC = 3600.0


def _resolution(v: tuple[int, ...]) -> tuple[int, int]:
    if len(v) != 2:
        raise PydanticCustomError("vector_length", "expected 2 values (width, height), got {got}", {"got": len(v)})
    if min(v) <= 0 or max(v) > MAX_IMG_SIDE:
        raise PydanticCustomError("resolution", "width and height must be in 1..{max}, got {v}",
                                  {"v": list(v), "max": MAX_IMG_SIDE})
    return (v[0], v[1])


Vec3 = _fixed_vector(3)
Vec4 = _fixed_vector(4)
Quat = _fixed_vector(4, quat_at=0)
Pose7 = _fixed_vector(7, quat_at=3)
FiniteList = Annotated[list[float], AfterValidator(_finite_list)]
ImgResolution = Annotated[tuple[int, ...], AfterValidator(_resolution)]
StrictInt = Annotated[int, Strict()]  # JSON true is not the integer 1


# Robot, cameras, scene -------------------------------------------------------------------


class RobotSpec(_Model):
    """Which robot, and its initial joint positions per move group (``{"arm": [...], ...}``).

    The robot's world placement is ``task.robot_base_pose``.
    """

    robot_name: str
    init_qpos: dict[str, FiniteList]


class RobotMountedCameraSpec(_Model):
    """A camera attached to robot bodies: offset and look-at point relative to them."""

    name: str = Field(min_length=1)
    type: Literal["robot_mounted"] = "robot_mounted"
    reference_body_names: list[str]
    camera_offset: Vec3
    lookat_offset: Vec3
    camera_quaternion: Quat  # wxyz
    fov: float  # vertical field of view, degrees
    record_depth: bool = False


class ExocentricCameraSpec(_Model):
    """A camera fixed in the world, given by position and up/forward directions."""

    name: str = Field(min_length=1)
    type: Literal["exocentric"] = "exocentric"
    pos: Vec3
    up: Vec3
    forward: Vec3
    fov: float  # vertical field of view, degrees
    record_depth: bool = False


def _camera_tag(v: Any) -> str | None:
    if isinstance(v, BaseModel):
        return getattr(v, "type", None)
    if not isinstance(v, dict):
        return None
    if "type" in v:
        return v["type"] if isinstance(v["type"], str) else None
    # Files without "type": an exocentric camera is the one with a world position.
    return "exocentric" if "pos" in v or "forward" in v else "robot_mounted"


CameraSpec = Annotated[
    Union[
        Annotated[RobotMountedCameraSpec, Tag("robot_mounted")],
        Annotated[ExocentricCameraSpec, Tag("exocentric")],
    ],
    Discriminator(
        _camera_tag,
        custom_error_type="camera_type",
        custom_error_message="unknown camera type (expected 'robot_mounted' or 'exocentric')",
    ),
]


class PrimitiveGeomSpec(_Model):
    """One MuJoCo geom of a procedurally built body (sizes zero-padded to 3)."""

    name_suffix: str
    geom_type: Literal["box", "sphere", "capsule", "cylinder", "ellipsoid"]
    size: Vec3
    rgba: Vec4
    contype: int | None = None
    conaffinity: int | None = None
    friction: FiniteList | None = None
    mass: float | None = None


class PrimitiveObjectSpec(_Model):
    """A body made of primitive geoms, added to the scene without an XML asset."""

    body_name: str
    initial_pos: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    add_freejoint: bool = True
    freejoint_name: str | None = None
    freejoint_damping: float | None = None
    geoms: list[PrimitiveGeomSpec]


class SceneModificationsSpec(_Model):
    """Edits to the base scene: objects to add (name -> MJCF path), poses to set, objects to remove."""

    added_objects: dict[str, str] = Field(default_factory=dict)
    primitive_objects: dict[str, PrimitiveObjectSpec] = Field(default_factory=dict)
    object_poses: dict[str, Pose7] = Field(default_factory=dict)
    removed_objects: list[str] = Field(default_factory=list)


# Tasks -----------------------------------------------------------------------------------


class BaseTaskSpec(_Model):
    """Fields every task has. ``task_cls`` (a dotted class path) is authoritative."""

    task_cls: str
    task_type: str | None = None
    robot_base_pose: Pose7
    task_horizon_sec: float | None = Field(default=None, gt=0, le=MAX_TASK_HORIZON_SEC)

    @property
    def task_name(self) -> str:
        """The key to look the task type up by in the plugin registry."""
        return molmospaces.task_name_for(self.task_cls, self.task_type)


class GenericTaskSpec(BaseTaskSpec):
    """A task whose class this schema does not know; its fields stay as given."""


class PickTaskSpec(BaseTaskSpec):
    """Pick: lift the object at least ``succ_pos_threshold`` metres, touching only the robot."""

    pickup_obj_name: str
    pickup_obj_start_pose: Pose7
    pickup_obj_goal_pose: Pose7 | None = None
    receptacle_name: str | None = None
    succ_pos_threshold: float = Field(default=0.01, ge=0)  # metres


class PickAndPlaceTaskSpec(PickTaskSpec):
    """Pick and place: the receptacle carries the object, the robot let go, the receptacle stayed put."""

    place_receptacle_name: str
    place_receptacle_start_pose: Pose7
    receptacle_supported_weight_frac: float = Field(default=0.5, ge=0, le=1)
    max_place_receptacle_pos_displacement: float = Field(default=0.15, ge=0)  # metres
    max_place_receptacle_rot_displacement: float = Field(default=math.radians(60), ge=0)  # radians, yaw ignored


def _gap_default(default: float) -> Any:
    """A surface gap in metres; ``null`` in a file means the task's default."""
    return Annotated[float, BeforeValidator(lambda v: default if v is None else v)]


class PickAndPlaceNextToTaskSpec(PickAndPlaceTaskSpec):
    """Next to: the object ends beside the receptacle, XY surface gap within [min, max]."""

    min_surface_to_surface_gap: _gap_default(0.0) = 0.0
    max_surface_to_surface_gap: _gap_default(0.05) = 0.05


class PickAndPlaceColorTaskSpec(PickAndPlaceTaskSpec):
    """Pick and place where receptacles are told apart by colour (rgba per object)."""

    object_colors: dict[str, Vec4] | None = None
    other_receptacle_names: list[str] | None = None
    other_receptacle_start_poses: dict[str, Pose7] | None = None


class OpenCloseTaskSpec(BaseTaskSpec):
    """Open / close an articulated object; success on the opening fraction of its joint."""

    pickup_obj_name: str
    pickup_obj_start_pose: Pose7
    articulation_object_name: str | None = None
    joint_name: str
    joint_index: int = 0
    joint_start_position: float | list[float]
    joint_goal_position: float | None = None
    task_success_threshold: float = Field(default=0.20, ge=0, le=1)  # opening fraction
    any_inst_of_category: bool = False


class DoorOpeningTaskSpec(BaseTaskSpec):
    """Open a door to at least ``door_openness_threshold`` of its joint range."""

    door_body_name: str
    articulated_joint_range: FiniteList | None = None
    articulated_joint_reset_state: FiniteList | None = None
    door_openness_threshold: float = Field(default=0.67, ge=0, le=1)  # opening fraction


class NavToObjTaskSpec(BaseTaskSpec):
    """Navigate to within ``succ_pos_threshold`` metres of a visible candidate object."""

    pickup_obj_name: str
    pickup_obj_candidates: list[str] | None = None
    pickup_obj_start_pose: Pose7 | None = None
    receptacle_name: str | None = None
    succ_pos_threshold: float = Field(default=1.5, ge=0)  # metres


#: Task type name -> its spec model (every MolmoSpaces task).
TASK_SPECS: dict[str, type[BaseTaskSpec]] = {
    "pick": PickTaskSpec,
    "pick_and_place": PickAndPlaceTaskSpec,
    "pick_and_place_next_to": PickAndPlaceNextToTaskSpec,
    "pick_and_place_color": PickAndPlaceColorTaskSpec,
    "open": OpenCloseTaskSpec,
    "close": OpenCloseTaskSpec,
    "door_opening": DoorOpeningTaskSpec,
    "nav_to_obj": NavToObjTaskSpec,
}
_SPEC_TAGS = {cls: name for name, cls in reversed(TASK_SPECS.items())}


#: Our own task classes (benchmarks made by ``molmo-bench generate``) -> task type name.
NATIVE_TASK_CLS: dict[str, str] = {
    "molmo_lerobot.tasks.pick.PickTask": "pick",
    "molmo_lerobot.tasks.pick_and_place.PickAndPlaceTask": "pick_and_place",
    "molmo_lerobot.tasks.pick_and_place.PickAndPlaceNextToTask": "pick_and_place_next_to",
    "molmo_lerobot.tasks.pick_and_place.PickAndPlaceColorTask": "pick_and_place_color",
}


def known_task_type(task_cls: Any, task_type: Any = None) -> str | None:
    """Our task type name for a task dict: by a known ``task_cls``, else by a known ``task_type``."""
    task_type = task_type if isinstance(task_type, str) else None
    name = None
    if isinstance(task_cls, str):
        name = NATIVE_TASK_CLS.get(task_cls) or molmospaces.known_task_name(task_cls, task_type)
    if name is None and task_type is not None:
        name = molmospaces.known_task_name(task_type)
    return name


def task_spec_model(task_cls: Any, task_type: Any = None) -> type[BaseTaskSpec]:
    """The spec model for a task dict: by a known ``task_cls``, else by a known ``task_type``."""
    return TASK_SPECS.get(known_task_type(task_cls, task_type), GenericTaskSpec)


def _task_tag(v: Any) -> str:
    if isinstance(v, BaseModel):
        return _SPEC_TAGS.get(type(v), "generic")
    if not isinstance(v, dict):
        return "generic"
    model = task_spec_model(v.get("task_cls"), v.get("task_type"))
    return _SPEC_TAGS.get(model, "generic")


#: Tags inserted into validation error locations by the discriminated unions.
UNION_TAGS = frozenset({"generic", "robot_mounted", "exocentric", *(_SPEC_TAGS.values())})

TaskSpec = Annotated[
    Union[
        Annotated[PickAndPlaceNextToTaskSpec, Tag("pick_and_place_next_to")],
        Annotated[PickAndPlaceColorTaskSpec, Tag("pick_and_place_color")],
        Annotated[PickAndPlaceTaskSpec, Tag("pick_and_place")],
        Annotated[PickTaskSpec, Tag("pick")],
        Annotated[OpenCloseTaskSpec, Tag("open")],
        Annotated[DoorOpeningTaskSpec, Tag("door_opening")],
        Annotated[NavToObjTaskSpec, Tag("nav_to_obj")],
        Annotated[GenericTaskSpec, Tag("generic")],
    ],
    Discriminator(_task_tag),
]


# Language, provenance, episode -----------------------------------------------------------


class LanguageSpec(_Model):
    """The instruction, and referral expressions per task object field."""

    task_description: str
    referral_expressions: dict[str, str] = Field(default_factory=dict)
    # field -> [[clip score difference, clip score, expression], ...]
    referral_expressions_priority: dict[str, list[list[float | str]]] = Field(default_factory=dict)


class SourceSpec(_Model):
    """Where an episode came from (a recorded trajectory, for MolmoSpaces-made benchmarks)."""

    h5_file: str
    traj_key: str
    episode_length: int | None = None
    camera_system_class: str | None = None
    source_data_date: str | None = None
    benchmark_created_date: str | None = None


class EpisodeSpec(_Model):
    """Everything needed to recreate one episode's initial conditions.

    Timing (policy/control/physics dt) and the horizon are evaluation settings, not here;
    ``task.task_horizon_sec`` is an optional hint that newer files carry.
    """

    source: SourceSpec | None = None
    house_index: StrictInt
    scene_dataset: str
    data_split: str = "val"
    seed: int | None = None
    robot: RobotSpec
    img_resolution: ImgResolution  # (width, height)
    cameras: list[CameraSpec] = Field(default_factory=list)
    scene_modifications: SceneModificationsSpec = Field(default_factory=SceneModificationsSpec)
    task: TaskSpec
    task_relevant_objects: list[str] = Field(default_factory=list)
    language: LanguageSpec

    @property
    def task_name(self) -> str:
        """Registry key of this episode's task type (see :attr:`BaseTaskSpec.task_name`)."""
        return self.task.task_name

    @property
    def prompt(self) -> str:
        return self.language.task_description

    def camera(self, name: str) -> RobotMountedCameraSpec | ExocentricCameraSpec:
        for cam in self.cameras:
            if cam.name == name:
                return cam
        raise KeyError(f"no camera {name!r} in episode (cameras: {', '.join(c.name for c in self.cameras) or 'none'})")


class BenchmarkMetadata(_Model):
    """Optional ``benchmark_metadata.json``: descriptive, never needed to run an episode."""

    name: str | None = None
    description: str | None = None
    created_at: str | None = None
    source_datagen_path: str | None = None
    num_episodes: int | None = None
    num_houses: int | None = None
    task_cls_counts: dict[str, int] | None = None
    object_category_counts: dict[str, int] | None = None
    robot_counts: dict[str, int] | None = None
    episode_length_stats: dict[str, float] | None = None
    house_counts: dict[int, int] | None = None
    camera_system_class: str | None = None
    source_data_date: str | None = None
    benchmark_created_date: str | None = None


def episode_digest(episode: EpisodeSpec | dict[str, Any]) -> bytes:
    """SHA-256 of an episode's content (its JSON, keys sorted): what seeds its randomizations."""
    data = episode.model_dump(mode="json") if isinstance(episode, BaseModel) else episode
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).digest()
