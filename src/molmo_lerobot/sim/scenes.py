"""Scene datasets: what an episode's ``scene_dataset`` + ``house_index`` build with MjSpec.

A :class:`SceneDataset` is what a scene plugin returns from ``molmo_scene_datasets()``.
``build(house_index)`` returns a fresh world spec (no robot, no cameras); ``metadata``
describes the house: which bodies are objects and which asset each one is (MolmoSpaces'
scene metadata), where the robot stands, and the region where objects may be placed.
The per-episode methods also get the run's :class:`SceneContext` (where its data lives).
"""

from __future__ import annotations

import warnings
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, Protocol

import mujoco

if TYPE_CHECKING:
    from molmo_lerobot.assets.catalog import AssetCatalog
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.molmospaces.settings import MolmoSpacesSettings


class SceneContext(Protocol):
    """What a scene dataset may read of the run (a :class:`~molmo_lerobot.context.RunContext` is one)."""

    @property
    def settings(self) -> MolmoSpacesSettings:
        """Where MolmoSpaces data lives and how its scenes load (assets dir, user scenes, physics options)."""

    @property
    def catalog(self) -> AssetCatalog:
        """The run's asset libraries (objects added by UID are installed through them)."""


class SceneDataset(ABC):
    """A family of scenes indexed by ``house_index``."""

    name: str
    aliases: tuple[str, ...] = ()
    #: whether its episodes run with MuJoCo body sleeping where the run leaves ``timing.sleep`` unset
    #: (MolmoSpaces' scene datasets: yes, as their rollouts; ours: no, docs/parity.md)
    sleeps: bool = False

    @abstractmethod
    def n_houses(self) -> int | None:
        """How many houses exist (``None`` for an unbounded procedural family)."""

    @abstractmethod
    def build(self, house_index: int) -> mujoco.MjSpec:
        """A fresh world spec for this house, deterministic in ``house_index``."""

    @abstractmethod
    def metadata(self, house_index: int) -> dict[str, Any]:
        """House description, JSON-ready. At least ``objects``: ``{body_name: {"asset_id": uid, ...}}``."""

    def missing(self, spec: EpisodeSpec, ctx: SceneContext) -> str | None:
        """Why ``spec``'s scene cannot load here (what, where, how to get it), or ``None``: checked by
        ``molmo-bench validate`` before any simulation; none by default."""
        return None

    def install_problem(self) -> str | None:
        """One line naming a fault of the installed files the dataset reads in place (and how to
        repair it), or ``None``; checked once per run before any worker starts, and again when an
        episode's scene fails to build (a fault then is infrastructure, not the episode's)."""
        return None

    # Per episode (datasets whose houses depend on more than the index override these) ----------
    def build_episode(self, spec: EpisodeSpec, ctx: SceneContext) -> mujoco.MjSpec:
        """The world spec of ``spec``'s house (default: :meth:`build` of its ``house_index``)."""
        return self.build(spec.house_index)

    def episode_metadata(self, spec: EpisodeSpec, ctx: SceneContext) -> dict[str, Any]:
        """The metadata of ``spec``'s house (default: :meth:`metadata` of its ``house_index``)."""
        return self.metadata(spec.house_index)

    def episode_source(self, spec: EpisodeSpec, ctx: SceneContext) -> str:
        """What of the run decides how ``spec``'s house builds, beyond the episode (part of the compiled
        model's cache key; default: nothing, the house index decides)."""
        return ""

    def modify(self, world: mujoco.MjSpec, spec: EpisodeSpec, ctx: SceneContext) -> None:
        """Apply ``scene_modifications``: remove bodies (exact names), attach added MJCF files."""
        mods = spec.scene_modifications
        for name in mods.removed_objects:
            body = world.body(name)
            if body is None:
                raise ValueError(f"scene_modifications.removed_objects: no body {name!r} in house {spec.house_index}")
            world.delete(body)
        for name, xml in mods.added_objects.items():
            attach_mjcf(world, xml, name, source=f"scene_modifications.added_objects[{name!r}]")

    def physics_options(self, defaults: dict[str, Any], ctx: SceneContext) -> dict[str, Any]:
        """Solver options to set on the compiled model (default: ``defaults``, the shared ones)."""
        return defaults

    def check_house(self, house_index: int) -> None:
        """Raise a clear ``ValueError`` if ``house_index`` is out of range."""
        n = self.n_houses()
        if house_index < 0 or (n is not None and house_index >= n):
            bound = f"0..{n - 1}" if n is not None else ">= 0"
            raise ValueError(f"scene dataset {self.name!r}: house_index {house_index} out of range ({bound})")


def room_spec(model_name: str, floor_rgb: Any) -> mujoco.MjSpec:
    """An empty world every procedural scene starts from: headlight and a floor of ``floor_rgb``."""
    world = mujoco.MjSpec()
    world.modelname = model_name
    world.visual.headlight.ambient = [0.35, 0.35, 0.35]
    world.visual.headlight.diffuse = [0.4, 0.4, 0.4]
    world.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3.0, 3.0, 0.05],
                             rgba=[*floor_rgb, 1.0])
    return world


def attach_mjcf(world: mujoco.MjSpec, xml: str, body_name: str, pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0),
                source: str = "object") -> None:
    """Attach the first top-level body of an MJCF document to ``world``, renamed ``body_name``.

    Every other element of the child gets the prefix ``"<body_name>/"`` so that names of
    different objects never collide. ``xml`` is MJCF text or a path to an MJCF file.
    """
    try:
        child = mujoco.MjSpec.from_file(xml) if not xml.lstrip().startswith("<") else mujoco.MjSpec.from_string(xml)
    except Exception as exc:
        raise ValueError(f"{source}: cannot parse MJCF for {body_name!r}: {str(exc).strip().splitlines()[0]}") from None
    top = child.worldbody.first_body()
    if top is None:
        raise ValueError(f"{source}: MJCF for {body_name!r} has no body")
    original = top.name
    frame = world.worldbody.add_frame(pos=list(pos), quat=list(quat))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        frame.attach_body(top, f"{body_name}/", "")
    world.body(f"{body_name}/{original}").name = body_name
