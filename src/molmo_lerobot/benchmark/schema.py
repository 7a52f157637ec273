"""Pydantic models of a benchmark episode, following MolmoSpaces' JSON benchmark schema.

A MolmoSpaces benchmark file validates here unchanged: field names, types and defaults
match theirs, and every model keeps unknown fields (``extra="allow"``). Poses are
``[x, y, z, qw, qx, qy, qz]``; vectors have fixed lengths and must be finite.

Task specs belong to the task plugins: each task type names its model (a subclass of
:class:`BaseTaskSpec`, built from the field types here). ``EpisodeSpec.task`` is validated
with the model that the validation context's :data:`TASK_MODEL` picks, which
:func:`molmo_lerobot.benchmark.task_specs.parse_episode` looks up in the plugin registry;
without it (or for a task no plugin knows) the task is a :class:`GenericTaskSpec`, so that
validation against the installed plugins, not parsing, reports it (with a "did you mean").
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    PlainValidator,
    SerializeAsAny,
    Strict,
    Tag,
    TypeAdapter,
    ValidationInfo,
)
from pydantic_core import PydanticCustomError

from molmo_lerobot.benchmark import molmospaces


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow")


# Vectors ---------------------------------------------------------------------------------


def _fixed_vector(n: int, quat_at: int | None = None) -> AfterValidator:
    """Checks a ``list[float]`` has exactly ``n`` finite values (with a non-zero quaternion at ``quat_at``)."""

    def check(v: list[float]) -> list[float]:
        if len(v) != n:
            raise PydanticCustomError("vector_length", "expected {n} values, got {got}", {"n": n, "got": len(v)})
        if not all(math.isfinite(x) for x in v):
            raise PydanticCustomError("vector_finite", "values must be finite, got {v}", {"v": v})
        if quat_at is not None and sum(x * x for x in v[quat_at : quat_at + 4]) < 1e-12:
            raise PydanticCustomError("zero_quaternion", "quaternion (qw, qx, qy, qz) must not be all zero", {})
        return v

    return AfterValidator(check)


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


Vec3 = Annotated[list[float], _fixed_vector(3)]
Vec4 = Annotated[list[float], _fixed_vector(4)]
Quat = Annotated[list[float], _fixed_vector(4, quat_at=0)]
Pose7 = Annotated[list[float], _fixed_vector(7, quat_at=3)]
FiniteList = Annotated[list[float], AfterValidator(_finite_list)]
if TYPE_CHECKING:
    ImgResolution = tuple[int, int]  # what validation gives
else:  # any length is parsed, so that a wrong one fails with our message
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
    Annotated[RobotMountedCameraSpec, Tag("robot_mounted")] | Annotated[ExocentricCameraSpec, Tag("exocentric")],
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
    """A task no installed plugin gives a spec model (or parsed without plugins); its fields stay as given."""


#: Our own task classes (benchmarks made by ``molmo-bench generate``) -> task type name.
NATIVE_TASK_CLS: dict[str, str] = {
    "molmo_lerobot.tasks.pick.PickTask": "pick",
    "molmo_lerobot.tasks.pick_and_place.PickAndPlaceTask": "pick_and_place",
    "molmo_lerobot.tasks.pick_and_place.PickAndPlaceNextToTask": "pick_and_place_next_to",
    "molmo_lerobot.tasks.pick_and_place.PickAndPlaceColorTask": "pick_and_place_color",
}


def known_task_type(task_cls: Any, task_type: Any = None) -> str | None:
    """Our task type name for a task dict (a label for episodes no plugin resolves): by a known
    ``task_cls``, else by a known ``task_type``."""
    task_type = task_type if isinstance(task_type, str) else None
    name = None
    if isinstance(task_cls, str):
        name = NATIVE_TASK_CLS.get(task_cls) or molmospaces.known_task_name(task_cls, task_type)
    if name is None and task_type is not None:
        name = molmospaces.known_task_name(task_type)
    return name


#: Validation-context key of the function that picks the spec model of ``EpisodeSpec.task``:
#: ``task dict -> (tag, model)``; the tag (the task type's name) prefixes error locations.
TASK_MODEL = "task_model"


def _typed_task(value: Any, info: ValidationInfo) -> BaseTaskSpec:
    """``value`` validated with the spec model the context picks for it (else GenericTaskSpec);
    a spec model instance is kept as it is."""
    if isinstance(value, BaseTaskSpec):
        return value
    pick = (info.context or {}).get(TASK_MODEL)
    tag, model = pick(value) if pick is not None and isinstance(value, dict) else ("generic", GenericTaskSpec)
    # Validated as {tag: value}, so that errors name the tag, as a discriminated union's do.
    adapter = TypeAdapter(dict[str, model])  # type: ignore[valid-type]  # the model is picked at run time
    return adapter.validate_python({tag: value}, context=info.context)[tag]


#: A task spec: the model of the task's plugin (see :data:`TASK_MODEL`), dumped as that model.
TaskSpec = Annotated[SerializeAsAny[BaseTaskSpec], PlainValidator(_typed_task)]


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

    def edited(self, data: dict[str, Any]) -> EpisodeSpec:
        """``data`` (this episode's dump, edited) validated, its task with this episode's task model."""
        tag, model = self.task_name, type(self.task)
        return EpisodeSpec.model_validate(data, context={TASK_MODEL: lambda _task: (tag, model)})

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
    #: the render profile its episodes are seen through (``None``: ``v2``, every scene as it builds;
    #: :mod:`molmo_lerobot.sim.render_profile`)
    render_profile: str | None = None
