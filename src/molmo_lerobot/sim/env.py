"""The simulation environment: one episode's MuJoCo model and data, stepped at the policy rate.

``make_env(spec, timing, scene, robot, cameras)`` assembles the scene with MjSpec from the
plugin objects the caller resolved (this module never looks plugins up) — scene dataset house
→ robot at ``task.robot_base_pose`` on its pedestal (``RobotType.place``) →
``scene_modifications`` → cameras — and compiles it
with the physics timestep set from ``timing.sim_dt_ms`` (never taken from any XML) and
the solver options every scene shares (:data:`PHYSICS_OPTIONS`: the ``implicitfast``
integrator for stiff position actuators, elliptic friction cones and ``impratio`` 10 so
that grasped objects do not creep out of the fingers), unless the scene dataset keeps its
scenes' own (``SceneDataset.physics_options``: MolmoSpaces' scene XMLs).

One :meth:`Env.step` is one policy step: ``policy_dt / ctrl_dt`` controller ticks, each
followed by ``ctrl_dt / sim_dt`` physics steps. ``Timing.control`` says how the step's
position targets reach the actuators: ``hold`` (MolmoSpaces' controllers) writes the new
targets at the first tick and holds them for the step (the default); ``ramp`` moves them
linearly from the previous command to the new one over the ticks. ``Timing.sleep`` enables MuJoCo's
body sleeping from the reset state on, as MolmoSpaces' rollouts do (where the MuJoCo in use
has it). A run decides it per benchmark (``timing.sleep``, else the scene datasets'
``SceneDataset.sleeps``: on for MolmoSpaces' scenes, off for ours, whose contact-based success
rules read ``data.contact``, which leaves out a sleeping body's contacts: a settled object reads
as unsupported; ``docs/parity.md``).
"""

from __future__ import annotations

import copy
import json
import math
import warnings
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from molmo_lerobot.poses import pose7, unit_pose
from molmo_lerobot.sim.geometry import subtree
from molmo_lerobot.sim.render import process_renderer
from molmo_lerobot.sim.render_profile import RenderProfile, resolve_profile
from molmo_lerobot.sim.spec_compat import set_joint_damping

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.cameras.base import CameraSystem
    from molmo_lerobot.robots.base import RobotType
    from molmo_lerobot.sim.scenes import SceneContext, SceneDataset

PHYSICS_OPTIONS = {"integrator": mujoco.mjtIntegrator.mjINT_IMPLICITFAST, "cone": mujoco.mjtCone.mjCONE_ELLIPTIC,
                   "impratio": 10.0}


def _ratio(num: float, den: float, what: str) -> int:
    r = num / den
    n = round(r)
    if n < 1 or abs(r - n) > 1e-9 * max(1.0, r):
        raise ValueError(f"timing: {what} must be a whole multiple, got {num:g} / {den:g} = {r:g}")
    return int(n)


#: how a policy step's targets reach the actuators (see the module docstring)
CONTROL_MODES = ("hold", "ramp")
#: whose success rules the tasks apply (``task_rules``): MolmoSpaces' as their code has them, quirks
#: included, or ours where we corrected one (a task's ``parity_notes`` say where the two differ)
TASK_RULES = ("molmospaces", "fixed")
#: MolmoSpaces' sleep tolerance for rollouts (MuJoCo 3.5's default is 1e-4, 4.0's 1e-3)
SLEEP_TOLERANCE = 1e-3


def sleep_supported() -> bool:
    """Whether the MuJoCo in use can put bodies to sleep (``mjENBL_SLEEP``)."""
    return hasattr(mujoco.mjtEnableBit, "mjENBL_SLEEP")


@dataclass(frozen=True)
class Timing:
    """Policy, controller and physics periods in milliseconds (MolmoSpaces: 66 / 2 / 2), how
    targets are applied over a policy step (``control``) and whether bodies may sleep."""

    policy_dt_ms: float = 66.0
    ctrl_dt_ms: float = 2.0
    sim_dt_ms: float = 2.0
    control: str = "hold"
    sleep: bool = False

    def __post_init__(self) -> None:
        for name in ("policy_dt_ms", "ctrl_dt_ms", "sim_dt_ms"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"timing: {name} must be a positive number, got {value!r}")
        if self.control not in CONTROL_MODES:
            raise ValueError(f"timing: control must be one of {', '.join(CONTROL_MODES)}, got {self.control!r}")
        if not isinstance(self.sleep, bool):
            raise ValueError(f"timing: sleep must be true or false, got {self.sleep!r}")
        _ratio(self.policy_dt_ms, self.ctrl_dt_ms, "policy_dt_ms / ctrl_dt_ms")
        _ratio(self.ctrl_dt_ms, self.sim_dt_ms, "ctrl_dt_ms / sim_dt_ms")

    @property
    def ctrl_ticks(self) -> int:
        """Controller ticks per policy step."""
        return _ratio(self.policy_dt_ms, self.ctrl_dt_ms, "policy_dt_ms / ctrl_dt_ms")

    @property
    def substeps(self) -> int:
        """Physics steps per controller tick."""
        return _ratio(self.ctrl_dt_ms, self.sim_dt_ms, "ctrl_dt_ms / sim_dt_ms")

    @property
    def sim_dt_s(self) -> float:
        return self.sim_dt_ms / 1000.0

    @property
    def policy_dt_s(self) -> float:
        return self.policy_dt_ms / 1000.0


# Scene assembly --------------------------------------------------------------------------------

#: compiled models by scene-defining content; episodes of one house share the compilation
_MODEL_CACHE: OrderedDict[str, tuple[mujoco.MjModel, list[str]]] = OrderedDict()
_MODEL_CACHE_SIZE = 4


def _model_key(spec: EpisodeSpec, timing: Timing, scene: SceneDataset, robot: RobotType,
               cameras: CameraSystem, profile: RenderProfile, ctx: SceneContext) -> str:
    mods = spec.scene_modifications.model_dump(mode="json", exclude={"object_poses"})
    return json.dumps([spec.scene_dataset, spec.data_split, spec.house_index, scene.episode_source(spec, ctx),
                       robot.name,
                       vars(robot),  # a configured robot's settings (rby1: where its model is read from)
                       spec.task.robot_base_pose,
                       robot.base_size(spec.robot),
                       list(spec.img_resolution), [c.model_dump(mode="json") for c in spec.cameras], mods,
                       timing.sim_dt_ms, type(scene).__qualname__, cameras.name,
                       cameras.episode_key(spec), profile.record()], sort_keys=True, default=str)


def _add_primitive(world: mujoco.MjSpec, name: str, prim: Any) -> None:
    body = world.worldbody.add_body(name=prim.body_name or name, pos=list(prim.initial_pos))
    if prim.add_freejoint:
        joint = body.add_freejoint(name=prim.freejoint_name or f"{body.name}/free")
        if prim.freejoint_damping is not None:
            set_joint_damping(joint, prim.freejoint_damping)
    types = {"box": mujoco.mjtGeom.mjGEOM_BOX, "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
             "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE, "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
             "ellipsoid": mujoco.mjtGeom.mjGEOM_ELLIPSOID}
    for g in prim.geoms:
        geom = body.add_geom(name=f"{body.name}{g.name_suffix}", type=types[g.geom_type], size=list(g.size),
                             rgba=list(g.rgba))
        for attr in ("contype", "conaffinity", "mass"):
            if getattr(g, attr) is not None:
                setattr(geom, attr, getattr(g, attr))
        if g.friction is not None:
            geom.friction = list(g.friction) + [0.005, 0.0001][: max(0, 3 - len(g.friction))]


def _build_model(spec: EpisodeSpec, timing: Timing, scene: SceneDataset, robot: RobotType,
                 camera_system: CameraSystem, ctx: SceneContext,
                 profile: RenderProfile) -> tuple[mujoco.MjModel, list[str]]:
    world = scene.build_episode(spec, ctx)
    robot.place(world, spec)
    mods = spec.scene_modifications
    scene.modify(world, spec, ctx)
    for name, prim in mods.primitive_objects.items():
        _add_primitive(world, name, prim)
    body_names = [b.name for b in world.bodies]

    def find_body(name: str) -> mujoco.MjsBody | None:
        if name in body_names:
            return world.body(name)
        suffixed = [n for n in body_names if n.endswith("/" + name)]
        return world.body(suffixed[0]) if len(suffixed) == 1 else None

    cams = camera_system.add_cameras(world, spec.cameras, find_body, episode=spec)
    width, height = spec.img_resolution
    world.visual.global_.offwidth = max(world.visual.global_.offwidth, int(width))
    world.visual.global_.offheight = max(world.visual.global_.offheight, int(height))
    world.option.timestep = timing.sim_dt_s
    for option, value in scene.physics_options(PHYSICS_OPTIONS, ctx).items():
        setattr(world.option, option, value)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        try:
            model = world.compile()
        except ValueError as exc:
            raise ValueError(f"scene {spec.scene_dataset!r} house {spec.house_index} does not compile: "
                             f"{str(exc).strip().splitlines()[-1]}") from None
    profile.apply(model)
    return model, cams


def _place_cameras(spec: EpisodeSpec, timing: Timing, model: mujoco.MjModel, robot: RobotType, cams: list[str],
                   camera_system: CameraSystem) -> None:
    """Let ``camera_system`` place its cameras in the reset scene (on a scratch copy), then fix
    the poses it chose in ``model``."""
    probe = Env(spec, timing, copy.copy(model), robot, list(cams), source=model)
    try:
        probe.reset(0)
        poses = camera_system.place(probe)
    finally:
        probe.close()
    for name, (pos, quat, fovy) in poses.items():
        cam = model.camera(name).id
        model.cam_pos[cam], model.cam_quat[cam], model.cam_fovy[cam] = pos, quat, fovy


def make_env(spec: EpisodeSpec, timing: Timing, scene: SceneDataset, robot: RobotType,
             camera_system: CameraSystem, ctx: SceneContext, profile: RenderProfile | None = None) -> Env:
    """Assemble, compile (cached per scene content and render profile) and wrap one episode's simulation.

    ``scene``, ``robot`` and ``camera_system`` are the plugin objects for the episode's
    ``scene_dataset``, ``robot.robot_name`` and chosen camera system, resolved by the caller;
    ``ctx`` is what the scene dataset reads of the run; ``profile`` the run's render profile
    (``None``: the default profile with this process's overrides).
    """
    profile = resolve_profile(None) if profile is None else profile
    key = _model_key(spec, timing, scene, robot, camera_system, profile, ctx)
    if key in _MODEL_CACHE:
        _MODEL_CACHE.move_to_end(key)
    else:
        model, cams = _build_model(spec, timing, scene, robot, camera_system, ctx, profile)
        if camera_system.places_in_scene:
            _place_cameras(spec, timing, model, robot, cams, camera_system)
        _MODEL_CACHE[key] = model, cams
        while len(_MODEL_CACHE) > _MODEL_CACHE_SIZE:
            _MODEL_CACHE.popitem(last=False)
    model, cams = _MODEL_CACHE[key]
    env = Env(spec, timing, copy.copy(model), robot, list(cams), source=model)
    env.camera_system = camera_system.name
    env._scene, env._scene_ctx = scene, ctx
    return env


# The environment ---------------------------------------------------------------------------------


class Env:
    """One episode's simulation. Built by :func:`make_env`; see the module docstring for timing."""

    def __init__(self, spec: EpisodeSpec, timing: Timing, model: mujoco.MjModel, robot: RobotType,
                 camera_names: list[str], source: mujoco.MjModel | None = None) -> None:
        if abs(model.opt.timestep - timing.sim_dt_s) > 1e-12:
            raise ValueError(f"model timestep {model.opt.timestep} differs from sim_dt_ms={timing.sim_dt_ms}")
        self.spec = spec
        self.timing = timing
        self.model = model
        #: the compiled model ``model`` copies: episodes of one house share its render context
        self._source = model if source is None else source
        self.data = mujoco.MjData(model)
        self.robot_type = robot
        self.robot = robot.bind(model)
        self.move_groups: dict[str, int] = dict(robot.move_groups)
        self.joint_names: dict[str, list[str]] = {g: list(n) for g, n in robot.joint_names.items()}
        self.camera_names = camera_names
        #: name of the camera system that built the cameras
        self.camera_system = ""
        #: whose success rules the episode's task applies (:data:`TASK_RULES`; the run's ``task_rules``)
        self.task_rules = TASK_RULES[0]
        self._scene: SceneDataset | None = None
        self._scene_ctx: SceneContext | None = None
        self._scene_metadata: dict[str, Any] | None = None
        self._depth_cameras = [c.name for c in spec.cameras if c.record_depth]
        #: frames of the current state by camera: each camera renders at most once per state
        self._frames: dict[str, np.ndarray] = {}
        self._frames_key = b""
        #: frames rendered (RGB, depth and segmentation), for tests and profiling
        self.renders = 0
        #: seconds this env spent making the process's GL context and its model's render context
        self.renderer_setup_s = 0.0
        self._view = self.camera_view_options()
        self.seed: int | None = None
        self.rng = np.random.default_rng()
        base = np.asarray(robot.base_pose(spec.task.robot_base_pose), dtype=np.float64)
        #: the robot base's world pose (x, y, z, qw, qx, qy, qz): where MolmoSpaces puts its base body
        self.base_pose = unit_pose(base)

    # Lifecycle -----------------------------------------------------------------------------------
    def reset(self, seed: int) -> None:
        """Initial state from the spec: robot ``init_qpos`` and ``object_poses``; deterministic.

        ``seed`` seeds :attr:`rng`, the stream plugins use for any per-episode randomization.
        """
        self.seed = int(seed)
        self.rng = np.random.default_rng(self.seed)
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        init = self.spec.robot.init_qpos
        groups = [*self.move_groups, *self.robot_type.held_groups]
        unknown = sorted(g for g, v in init.items() if g not in groups and v)  # MolmoSpaces: "base": []
        if unknown:
            raise ValueError(f"robot.init_qpos: unknown move group(s) {unknown} (robot has {sorted(groups)})")
        for group in groups:
            values = init.get(group) or self.robot_type.default_init_qpos[group]
            try:
                self.robot_type.set_init_qpos(self.robot, d, group, values)
            except ValueError as exc:
                raise ValueError(f"robot.init_qpos[{group!r}]: {exc}") from None
        for name, pose in self.spec.scene_modifications.object_poses.items():
            self._place(name, np.asarray(pose, dtype=np.float64))
        mujoco.mj_forward(m, d)
        if sleep_supported():  # after the reset state is computed, as MolmoSpaces' rollouts
            flag = int(mujoco.mjtEnableBit.mjENBL_SLEEP)
            if self.timing.sleep:
                m.opt.enableflags |= flag
                m.opt.sleep_tolerance = SLEEP_TOLERANCE
            else:
                m.opt.enableflags &= ~flag

    def _place(self, name: str, pose: np.ndarray) -> None:
        bid = self.body_id(name, f"scene_modifications.object_poses[{name!r}]")
        quat = pose[3:] / np.linalg.norm(pose[3:])
        jnt = self.model.body_jntadr[bid]
        if self.model.body_jntnum[bid] == 1 and self.model.jnt_type[jnt] == mujoco.mjtJoint.mjJNT_FREE:
            adr = self.model.jnt_qposadr[jnt]
            self.data.qpos[adr:adr + 3] = pose[:3]
            self.data.qpos[adr + 3:adr + 7] = quat
            self.data.qvel[self.model.jnt_dofadr[jnt]:self.model.jnt_dofadr[jnt] + 6] = 0.0
        elif self.model.body_jntnum[bid] == 0 and self.model.body_parentid[bid] == 0:
            self.model.body_pos[bid] = pose[:3]  # a static body: this env owns its model copy
            self.model.body_quat[bid] = quat
        else:
            raise ValueError(f"scene_modifications.object_poses[{name!r}]: body is neither free nor a static "
                             "top-level body")

    def close(self) -> None:
        """Drop this episode's frames (the process's GL context stays for the next episode)."""
        self._frames.clear()

    # Stepping ------------------------------------------------------------------------------------
    def _validate(self, action: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        if not isinstance(action, dict):
            raise ValueError(f"action must be a dict keyed by move group, got {type(action).__name__}")
        if set(action) != set(self.move_groups):
            raise ValueError(f"action has move groups {sorted(action)}, expected {sorted(self.move_groups)}")
        out = {}
        for group, dim in self.move_groups.items():
            a = np.asarray(action[group], dtype=np.float64)
            if a.shape != (dim,):
                raise ValueError(f"action[{group!r}] has shape {a.shape}, expected ({dim},)")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"action[{group!r}] has non-finite values: {a.tolist()}")
            out[group] = a
        return out

    def step(self, action: dict[str, np.ndarray]) -> None:
        """Run one policy step towards ``action`` (arm joint targets, gripper 0 open … 1 closed)."""
        target = self._validate(action)
        m, d = self.model, self.data
        start = d.ctrl.copy()
        for g, goal in target.items():
            self.robot.command(d, g, goal)
        ticks, substeps = self.timing.ctrl_ticks, self.timing.substeps
        if self.timing.control == "hold":
            mujoco.mj_step(m, d, nstep=ticks * substeps)
        else:
            delta = d.ctrl - start
            for k in range(1, ticks + 1):  # the robot's command maps are affine: interpolate in ctrl space
                d.ctrl[:] = start + delta * (k / ticks)
                mujoco.mj_step(m, d, nstep=substeps)
        if not np.all(np.isfinite(d.qpos)):
            raise RuntimeError(f"physics diverged at t={d.time:.3f}s (non-finite state)")

    # Observation ---------------------------------------------------------------------------------
    def observe(self, images: bool) -> dict[str, Any]:
        """The Observation of :mod:`molmo_lerobot.policies.base` (images rendered only if asked)."""
        d = self.data
        site = self.robot.tcp_site
        obs: dict[str, Any] = {
            "qpos": {g: self.robot.qpos(d, g) for g in self.move_groups},
            "qvel": {g: self.robot.qvel(d, g) for g in self.move_groups},
            "tcp_pose": pose7(d.site_xpos[site], d.site_xmat[site]),
            "robot_base_pose": self._base_now(),
            "joint_qpos": {g: self.robot.joint_qpos(d, g) for g in self.move_groups},
            "joint_qvel": {g: self.robot.joint_qvel(d, g) for g in self.move_groups},
        }
        if images:
            obs["images"] = {name: self.render(name) for name in self.camera_names}
            if self._depth_cameras:
                obs["depth"] = {name: self.render_depth(name) for name in self._depth_cameras}
        return obs

    def _base_now(self) -> np.ndarray:
        """The robot base's world pose: where a mobile robot has driven it, else :attr:`base_pose`."""
        moving = self.robot.base_pose(self.data)
        return self.base_pose.copy() if moving is None else np.asarray(moving, dtype=np.float64)

    @staticmethod
    def camera_view_options() -> mujoco.MjvOption:
        """What a real camera sees: geom groups 0-2 (visual meshes), no sites, frames or other markers."""
        opt = mujoco.MjvOption()
        opt.sitegroup[:] = 0
        opt.geomgroup[:] = 0
        opt.geomgroup[:3] = 1
        return opt

    def _state_key(self) -> bytes:
        """What a frame depends on that a step, a reset or a task may change."""
        d, m = self.data, self.model
        return b"".join(a.tobytes() for a in (np.array([d.time]), d.qpos, d.mocap_pos, d.mocap_quat, m.cam_pos,
                                              m.cam_quat, m.cam_fovy, m.body_pos, m.body_quat))

    def _size(self) -> tuple[int, int]:
        width, height = self.spec.img_resolution
        return int(width), int(height)

    def _camera_id(self, camera: str) -> int:
        cid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if cid < 0:
            raise ValueError(f"The camera {camera!r} does not exist.")
        return cid

    def _renderer(self):
        renderer = process_renderer()
        before = renderer.setup_s
        self.renders += 1
        return renderer, before

    def render(self, camera: str) -> np.ndarray:
        """RGB uint8 image (H, W, 3) from ``camera``, rendered once per state: the policy, the recorder
        and ``render()`` of the Gymnasium env get the same frame (do not write into it)."""
        key = self._state_key()
        cached = self._frames.get(camera)
        if cached is not None and self._frames_key == key:
            return cached
        if self._frames_key != key:
            self._frames.clear()
            self._frames_key = key
        renderer, before = self._renderer()
        frame = renderer.rgb(self._source, self.model, self.data, self._camera_id(camera), self._view, self._size())
        self.renderer_setup_s += renderer.setup_s - before
        self._frames[camera] = frame
        return frame

    def visible_fractions(self, camera: str, bodies: Sequence[str]) -> dict[str, float]:
        """For each body, the fraction of ``camera``'s pixels showing a geom of its subtree
        (a segmentation render at the episode's resolution, what the camera sees)."""
        mujoco.mj_camlight(self.model, self.data)  # cameras the caller just moved
        renderer, before = self._renderer()
        geom_ids = renderer.geom_ids(self._source, self.model, self.data, self._camera_id(camera), self._view,
                                     self._size())
        self.renderer_setup_s += renderer.setup_s - before
        out = {}
        for name in bodies:
            owned = np.isin(self.model.geom_bodyid, list(self.subtree_bodies(name)))
            out[name] = float(np.isin(geom_ids, np.flatnonzero(owned)).mean())
        return out

    def render_depth(self, camera: str) -> np.ndarray:
        """Depth in metres, float32 (H, W), from ``camera``."""
        renderer, before = self._renderer()
        depth = renderer.depth(self._source, self.model, self.data, self._camera_id(camera), self._view, self._size())
        self.renderer_setup_s += renderer.setup_s - before
        return depth

    # Privileged access (tasks, scripted experts) --------------------------------------------------
    @property
    def scene_metadata(self) -> dict[str, Any]:
        """The episode's scene metadata from its scene dataset (``objects``: body -> asset_id, category, …)."""
        if self._scene_metadata is None:
            scene, ctx = self._scene, self._scene_ctx
            self._scene_metadata = (scene.episode_metadata(self.spec, ctx) if scene and ctx is not None
                                    else {"objects": {}})
        return self._scene_metadata

    def body_id(self, name: str, field: str = "body") -> int:
        bid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)
        if bid < 0:
            raise ValueError(f"{field}: no body {name!r} in the scene")
        return bid

    def body_pose(self, name: str) -> np.ndarray:
        """World pose ``[x, y, z, qw, qx, qy, qz]`` of body ``name``."""
        bid = self.body_id(name)
        return np.concatenate([self.data.xpos[bid], self.data.xquat[bid]])

    def subtree_bodies(self, name: str) -> frozenset[int]:
        """Ids of ``name`` and every body below it."""
        return subtree(self.model, self.body_id(name))

    def contact_bodies(self, bodies: frozenset[int]) -> set[int]:
        """Bodies (outside ``bodies``) in contact with any of ``bodies`` right now."""
        d, gb = self.data, self.model.geom_bodyid
        touching: set[int] = set()
        for i in range(d.ncon):
            c = d.contact[i]
            b1, b2 = int(gb[c.geom1]), int(gb[c.geom2])
            if b1 in bodies and b2 not in bodies:
                touching.add(b2)
            elif b2 in bodies and b1 not in bodies:
                touching.add(b1)
        return touching
