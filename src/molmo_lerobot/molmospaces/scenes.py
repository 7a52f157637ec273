"""The ``molmospaces`` plugin: MolmoSpaces' scene datasets ``ithor``, ``procthor-10k``,
``procthor-objaverse``, ``holodeck-objaverse``, their debug variants and ``user`` (the run's
``scene_xml_paths``), and its library types: ``thor``/``objaverse`` objects with their
``droid``/``droid_objaverse`` grasps (:mod:`.libraries`) and ``user``, the run's
``asset_libraries``/``grasp_libraries`` in MolmoSpaces' format (:mod:`.user`).

A house is the scene XML that :mod:`.layout` names, loaded with ``MjSpec.from_file`` so its
relative mesh/texture/``<attach>`` paths resolve, keeping the scene's own ``<option>`` (all but
the timestep, which always comes from ``sim_dt_ms``) unless ``molmospaces.physics_options``
overrides it. ``scene_modifications`` follow MolmoSpaces' task sampler: ``removed_objects``
match a top-level body by full name, ``…/name`` suffix or last name part, and a name not
found is skipped; ``added_objects`` are MJCF paths relative to the assets dir (or absolute),
installed by UID (the file stem) when missing; the added body takes the last part of its
name, the rest becomes the prefix of its elements, and it gets a free joint if it has none.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco

from molmo_lerobot import hookimpl
from molmo_lerobot.assets.catalog import AssetLibraryType, GraspLibraryType
from molmo_lerobot.assets.libraries import AssetError
from molmo_lerobot.molmospaces import layout, libraries, user
from molmo_lerobot.sim.scenes import SceneContext, SceneDataset

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.molmospaces.settings import MolmoSpacesSettings

#: Damping MolmoSpaces gives the free joint it adds to an added object that has none.
ADDED_FREEJOINT_DAMPING = 0.001

_ENUMS = {"integrator": (mujoco.mjtIntegrator, "mjINT_"), "cone": (mujoco.mjtCone, "mjCONE_"),
          "jacobian": (mujoco.mjtJacobian, "mjJAC_"), "solver": (mujoco.mjtSolver, "mjSOL_")}


def physics_option_values(options: dict[str, Any]) -> dict[str, Any]:
    """``molmospaces.physics_options`` as MjSpec option values (enum names like ``implicitfast``)."""
    out: dict[str, Any] = {}
    probe = mujoco.MjSpec().option
    for key, value in options.items():
        if key == "timestep":
            raise ValueError("molmospaces.physics_options.timestep: the timestep comes from timing.sim_dt_ms")
        if not hasattr(probe, key):
            raise ValueError(f"molmospaces.physics_options.{key}: not a MuJoCo <option> attribute")
        if key in _ENUMS and isinstance(value, str):
            enum, prefix = _ENUMS[key]
            member = getattr(enum, prefix + value.upper(), None)
            if member is None:
                names = [n.removeprefix(prefix).lower() for n in dir(enum) if n.startswith(prefix)]
                raise ValueError(f"molmospaces.physics_options.{key}: unknown value {value!r} "
                                 f"(one of {', '.join(names)})")
            value = member
        out[key] = value
    return out


class MolmoSpacesScenes(SceneDataset):
    """One MolmoSpaces scene dataset over the run's assets dir (see the module docstring).

    Its houses exist only under a run's settings: they are built per episode
    (:meth:`build_episode`), never by index alone. Its episodes sleep (:attr:`SceneDataset.sleeps`)
    as MolmoSpaces' rollouts do.
    """

    sleeps = True

    def __init__(self, name: str) -> None:
        self.name = name

    def n_houses(self) -> int | None:
        return None

    # Where a house is ---------------------------------------------------------------------------
    def scene_path(self, settings: MolmoSpacesSettings, house_index: int, data_split: str = "val") -> Path:
        """The scene XML of a house (raises :class:`~.layout.SceneLookupError` when it has none)."""
        return layout.scene_xml(settings.assets, self.name, data_split, house_index, settings.house_variant)

    def missing(self, spec: EpisodeSpec, ctx: SceneContext) -> str | None:
        """Why ``spec``'s scene cannot load here (what, where, how to get it), or ``None``."""
        try:
            path = self.scene_path(ctx.settings, spec.house_index, spec.data_split)
        except layout.SceneLookupError as exc:
            return str(exc)
        if path.is_file():
            return None
        command = layout.install_command(layout.install_source(self.name, spec.data_split), ctx.settings.assets)
        return (f"scene {self.name!r} {spec.data_split} house {spec.house_index}: {path} not found; install it with "
                f"`{command}` (runs fetch each house) or point MLSPACES_ASSETS_DIR (molmospaces.assets_dir=) at a "
                "MolmoSpaces assets dir")

    def fetch(self, spec: EpisodeSpec, ctx: SceneContext) -> None:
        """Install ``spec``'s scene now if its source was installed on demand (``--preset molmospaces``).

        Where the assets dir records the scene source as linked by a resource manager (ours or
        molmospaces-resources'), the archives holding the scene XML and its metadata are fetched
        into the cache and linked, as MolmoSpaces does per house. Failures leave the scene missing
        (:meth:`missing` then says so); nothing is fetched for sources installed otherwise.
        """
        settings = ctx.settings
        try:
            path = self.scene_path(settings, spec.house_index, spec.data_split)
        except layout.SceneLookupError:
            return
        if path.is_file() or self.name == layout.USER:
            return
        from molmo_lerobot.resources import ResourceError, ResourceManager
        from molmo_lerobot.resources import molmospaces as ms_resources

        try:
            manager = ResourceManager(settings.cache_dir or ms_resources.cache_dir(), settings.assets,
                                      settings.remote or ms_resources.BUCKET_URL, progress=False)
            source = path.parent.name
            version = manager.linked().get("scenes", {}).get(source)
            if version is None:
                return
            resource = f"scenes/{source}@{version}"
            meta = layout.expected_metadata_name(path)
            for rel in (path.name, meta):
                if manager.index(resource).archive_for_path(rel) is not None:
                    manager.ensure_path(resource, rel)
        except (ResourceError, OSError):
            return

    # SceneDataset -------------------------------------------------------------------------------
    def build(self, house_index: int) -> mujoco.MjSpec:
        raise ValueError(f"scene dataset {self.name!r}: houses are built per episode, under a run's settings")

    def metadata(self, house_index: int) -> dict[str, Any]:
        raise ValueError(f"scene dataset {self.name!r}: house metadata is read per episode, under a run's settings")

    def build_episode(self, spec: EpisodeSpec, ctx: SceneContext) -> mujoco.MjSpec:
        problem = self.missing(spec, ctx)
        if problem is not None:
            raise FileNotFoundError(problem)
        return self._load(self.scene_path(ctx.settings, spec.house_index, spec.data_split))

    def episode_metadata(self, spec: EpisodeSpec, ctx: SceneContext) -> dict[str, Any]:
        meta = layout.read_scene_metadata(self.scene_path(ctx.settings, spec.house_index, spec.data_split))
        objects = dict(meta["objects"])
        for name, rel in spec.scene_modifications.added_objects.items():
            objects[name] = {"asset_id": Path(rel).stem, "object_enum": "temp_object", "is_static": False}
        return {**meta, "objects": objects}

    def episode_source(self, spec: EpisodeSpec, ctx: SceneContext) -> str:
        """The scene file (the run's assets dir or ``scene_xml_paths`` choose it) and the run's physics options."""
        try:
            path = str(self.scene_path(ctx.settings, spec.house_index, spec.data_split))
        except layout.SceneLookupError:
            path = ""
        return json.dumps([path, ctx.settings.physics_options], sort_keys=True, default=str)

    def _load(self, path: Path) -> mujoco.MjSpec:
        try:
            return mujoco.MjSpec.from_file(str(path))
        except Exception as exc:
            raise ValueError(f"{path}: cannot load scene: {str(exc).strip().splitlines()[0]}") from None

    def modify(self, world: mujoco.MjSpec, spec: EpisodeSpec, ctx: SceneContext) -> None:
        mods = spec.scene_modifications
        for name in mods.removed_objects:
            body = _find_removed(world, name)
            if body is not None:  # MolmoSpaces skips names the scene does not have
                world.delete(body)
        for name, rel in mods.added_objects.items():
            _attach_added(world, name, resolve_object_file(rel, f"scene_modifications.added_objects[{name!r}]", ctx),
                          mods.object_poses.get(name))

    def physics_options(self, defaults: dict[str, Any], ctx: SceneContext) -> dict[str, Any]:
        return physics_option_values(ctx.settings.physics_options)


class UserScenes(MolmoSpacesScenes):
    """``scene_dataset: user``: house ``i`` is ``scene_xml_paths[i]`` of the run config."""

    def __init__(self) -> None:
        super().__init__(layout.USER)

    def scene_path(self, settings: MolmoSpacesSettings, house_index: int, data_split: str = "val") -> Path:
        paths = settings.scene_xml_paths
        if not 0 <= house_index < len(paths):
            raise layout.SceneLookupError(
                f"house_index {house_index} is beyond scene_xml_paths ({len(paths)} scene"
                f"{'s' * (len(paths) != 1)} configured; set scene_xml_paths=[...] in the run config)")
        return Path(paths[house_index])

    def missing(self, spec: EpisodeSpec, ctx: SceneContext) -> str | None:
        try:
            path = self.scene_path(ctx.settings, spec.house_index)
        except layout.SceneLookupError as exc:
            return str(exc)
        return None if path.is_file() else f"scene_xml_paths[{spec.house_index}]: {path} not found"


def resolve_object_file(rel: str, field: str, ctx: SceneContext) -> Path:
    """An added object's MJCF: ``rel`` under the assets dir (or absolute), else installed by UID."""
    path = ctx.settings.assets / rel
    if path.is_file():
        return path
    uid = Path(rel).stem
    try:
        installed = ctx.catalog.install_uid(uid).mjcf_path
    except AssetError as exc:
        raise FileNotFoundError(f"{field}: {path} not found and UID {uid!r} cannot be installed ({exc})") from None
    if installed is None or not Path(installed).is_file():
        raise FileNotFoundError(f"{field}: {path} not found and UID {uid!r} has no installed MJCF")
    return Path(installed)


def _find_removed(world: mujoco.MjSpec, name: str) -> mujoco.MjsBody | None:
    base = name.split("/")[-1]
    body = world.worldbody.first_body()
    while body is not None:
        n = body.name
        if n in (name, base) or n.endswith(f"/{name}") or n.endswith(f"/{base}"):
            return body
        body = world.worldbody.next_body(body)
    return None


def _attach_added(world: mujoco.MjSpec, name: str, path: Path, pose: list[float] | None) -> None:
    try:
        child = mujoco.MjSpec.from_file(str(path))
    except Exception as exc:
        raise ValueError(f"scene_modifications.added_objects[{name!r}]: cannot load {path}: "
                         f"{str(exc).strip().splitlines()[0]}") from None
    body = child.worldbody.first_body()
    if body is None:
        raise ValueError(f"scene_modifications.added_objects[{name!r}]: {path} has no body")
    parts = name.split("/")
    body.name = parts[-1]
    if body.first_joint() is None:
        body.add_joint(name="XYZ_jntfree", type=mujoco.mjtJoint.mjJNT_FREE, damping=ADDED_FREEJOINT_DAMPING)
    pos, quat = (pose[:3], pose[3:7]) if pose is not None else ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])
    frame = world.worldbody.add_frame(pos=list(pos), quat=list(quat))
    prefix = "/".join(parts[:-1]) + "/" if len(parts) > 1 else f"{name}/"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        frame.attach_body(body, prefix, "")
    if len(parts) == 1:
        world.body(prefix + name).name = name


@hookimpl
def molmo_scene_datasets() -> list[SceneDataset]:
    return [*(MolmoSpacesScenes(name) for name in layout.SCENE_DIRS), UserScenes()]


#: The run's user libraries go ahead of every other library.
USER_PRIORITY = 1000


@hookimpl
def molmo_asset_libraries() -> list[AssetLibraryType]:
    return [*libraries.asset_library_types(), AssetLibraryType("user", user.run_asset_libraries, USER_PRIORITY)]


@hookimpl
def molmo_grasp_libraries() -> list[GraspLibraryType]:
    return [*libraries.grasp_library_types(), GraspLibraryType("user", user.run_grasp_libraries, USER_PRIORITY)]
