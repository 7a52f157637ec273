"""``rby1`` and ``rby1m``: Rainbow Robotics' RB-Y1 as MolmoSpaces runs it (their ``RBY1`` robot,
``RBY1Config`` / ``RBY1MConfig`` and ``RBY1RobotView``), over MolmoSpaces' own model.

The model is in MolmoSpaces' gated assets and is never built here: it is read from their assets
dir (the run's ``molmospaces.assets_dir``, else ``$MLSPACES_ASSETS_DIR``, else ours), at
``robots/rby1/rby1_site_control.xml`` (``rby1``) or ``robots/rby1m/rby1_v1.2_site_control.xml``
(``rby1m``, the mecanum-wheel version; same names and control), where ``molmo-resources``
installs their ``robots`` sources. Without it the robot fails with a one-line error naming the
path and how to install it.

Built as their ``add_robot_to_scene`` builds it (holonomic base, ``use_holo_base``): the model's
``robot_0/base`` subtree (the file's names already carry the namespace) at the world origin, 5 mm
up, every body below it gravity-compensated (``gravcomp``); a world site ``robot_0/world`` and three
site-transmission position actuators that drive ``robot_0/base_site`` relative to it
(:data:`BASE_ACTUATORS`: x and y ±25 m, kp 25000; yaw ±π, kp 5000; damping ratio 0.5). The
model's slide joints ``base_x`` / ``base_y`` and hinge ``base_theta`` are the base's world x, y
and yaw; the base starts at ``task.robot_base_pose`` (their ``set_world_pose`` on the base
group: x, y and yaw; z, and ``init_qpos["base"]``, are not used), kept in the model as the site
``robot_0/start_pose``.

Move groups, their robot's controllers in order, all joint-position commands (their default
command modes): ``base`` (x, y m, yaw rad; a yaw target is wrapped to within ±π of the current
yaw, as their base group does), ``torso`` (``torso_0..5``, actuators ``link1_act..link6_act``),
``left_arm`` / ``right_arm`` (``<side>_arm_0..6``, actuators ``<side>_arm_1_act..7_act``),
``left_gripper`` / ``right_gripper`` (one value, 0 open … 1 closed: actuator
``<side>_finger_act`` from their open -0.05 to closed 0.0, read back from the finger
joints ``gripper_finger_<l|r>1/2`` as their inter-finger distance, 0.1 open … 0 closed).
``init_qpos`` takes their values: grippers in metres (``[-0.05]`` open, or the two finger
positions). Their ``head`` group (``head_0``, ``head_1``) takes no commands: it is held at
``init_qpos["head"]`` (:attr:`RBY1.held_groups`). The TCP is the right hand's ``ee_site_r``.

Their relative and torso-height command modes (``RBY1MOpenCloseConfig``) and wheel driving
(``use_holo_base=False``) are not offered. Cameras are the model's own (``head_camera``,
``wrist_camera_l`` / ``_r``, ``camera_follower``; :mod:`molmo_lerobot.cameras.rby1`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import ClassVar

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.paths import molmospaces_assets_dir
from molmo_lerobot.resources.molmospaces import VERSIONS
from molmo_lerobot.robots.base import RobotHandle, RobotType, planar_base_range
from molmo_lerobot.robots.mobile_franka import BASE_JOINTS, _yaw
from molmo_lerobot.sim.geometry import subtree

NAMESPACE = "robot_0/"
#: their ``robot_model_root_name()`` (the file's names carry the namespace)
ROOT_BODY = NAMESPACE + "base"
#: their insertion height (the wrapper body's offset their ``attach_body`` drops and re-applies)
INSERT_Z = 0.005
#: their holonomic base actuators: name -> (ctrl range ±, kp, bias damping ratio, gear axis)
BASE_ACTUATORS = {"base_x": (25.0, 25000.0, 0.5, 0), "base_y": (25.0, 25000.0, 0.5, 1),
                  "base_theta": (math.pi, 5000.0, 0.5, 5)}
#: their gripper ctrl: open, closed (finger 1's position, m); inter-finger distance when open
GRIPPER_OPEN, GRIPPER_CLOSED, FINGER_SPAN = -0.05, 0.0, 0.1
START_SITE = NAMESPACE + "start_pose"
SIDES = ("left", "right")


def _groups() -> dict[str, tuple[list[str], list[str]]]:
    """Their robot view's groups: name -> (joint names, actuator names), without the namespace."""
    groups = {"base": (list(BASE_JOINTS), [f"{j}_act" for j in BASE_JOINTS]),
              "torso": ([f"torso_{i}" for i in range(6)], [f"link{i + 1}_act" for i in range(6)])}
    for side in SIDES:
        groups[f"{side}_arm"] = ([f"{side}_arm_{i}" for i in range(7)], [f"{side}_arm_{i + 1}_act" for i in range(7)])
    for side in SIDES:
        groups[f"{side}_gripper"] = ([f"gripper_finger_{side[0]}{i + 1}" for i in range(2)], [f"{side}_finger_act"])
    groups["head"] = ([f"head_{i}" for i in range(2)], [f"head_{i}_act" for i in range(2)])
    return groups


GROUPS = _groups()


def model_path(name: str, xml: str, assets_dir: str | Path | None = None) -> Path:
    """Where their ``name`` robot's ``xml`` is in their assets dir (whether or not it is there)."""
    return molmospaces_assets_dir(assets_dir) / "robots" / name / xml


def load_model(name: str, xml: str, assets_dir: str | Path | None = None) -> mujoco.MjSpec:
    """Their model as a spec; ``FileNotFoundError`` (one line: the path, how to install) if absent."""
    path = model_path(name, xml, assets_dir)
    if not path.is_file():
        version = VERSIONS["robots"].get(name, "VERSION")
        raise FileNotFoundError(
            f"robot {name!r}: MolmoSpaces' model is not installed at {path} (it is in their gated assets: "
            f"`molmo-resources install robots/{name}@{version} --remote REMOTE --cache-dir CACHE --install-dir "
            f"{path.parents[2]}`, or `molmo-resources install --preset molmospaces`; or point "
            "molmospaces.assets_dir / MLSPACES_ASSETS_DIR at an assets dir that has it)")
    spec = mujoco.MjSpec.from_file(str(path))
    wanted = [(spec.body, ROOT_BODY), *((spec.site, NAMESPACE + s) for s in ("base_site", "ee_site_l", "ee_site_r"))]
    for group, (joints, actuators) in GROUPS.items():
        wanted += [(spec.joint, NAMESPACE + j) for j in joints]
        wanted += [] if group == "base" else [(spec.actuator, NAMESPACE + a) for a in actuators]
    missing = [name for find, name in wanted if find(name) is None]
    if missing:
        raise ValueError(f"{path}: not MolmoSpaces' RB-Y1 model as their robot view reads it: no {missing}")
    return spec


class RBY1Handle(RobotHandle):
    """Move-group access to a compiled model holding the RB-Y1 (module docstring)."""

    def __init__(self, model: mujoco.MjModel, name: str) -> None:
        self.robot_name = name
        self._q: dict[str, np.ndarray] = {}
        self._v: dict[str, np.ndarray] = {}
        self._u: dict[str, np.ndarray] = {}
        for group, (joints, actuators) in GROUPS.items():
            ids = [model.joint(NAMESPACE + j).id for j in joints]
            self._q[group] = np.array([model.jnt_qposadr[j] for j in ids])
            self._v[group] = np.array([model.jnt_dofadr[j] for j in ids])
            self._u[group] = np.array([model.actuator(NAMESPACE + a).id for a in actuators])
        self._lo = {g: np.where(model.actuator_ctrllimited[u].astype(bool), model.actuator_ctrlrange[u, 0], -np.inf)
                    for g, u in self._u.items()}
        self._hi = {g: np.where(model.actuator_ctrllimited[u].astype(bool), model.actuator_ctrlrange[u, 1], np.inf)
                    for g, u in self._u.items()}
        self._tcp = model.site(NAMESPACE + "ee_site_r").id
        self._base = model.body(ROOT_BODY).id
        self._bodies = subtree(model, self._base)
        start = model.site(START_SITE).id
        quat = model.site_quat[start]
        self._start = np.array([*model.site_pos[start][:2],
                                math.atan2(2 * (quat[0] * quat[3] + quat[1] * quat[2]),
                                           1 - 2 * (quat[2] ** 2 + quat[3] ** 2))])

    def _check(self, group: str) -> None:
        if group not in self._q:
            raise KeyError(f"{self.robot_name} has groups {list(self._q)}, not {group!r}")

    @staticmethod
    def _gripper(group: str) -> bool:
        return group.endswith("_gripper")

    def qpos(self, data, group):
        self._check(group)
        q = data.qpos[self._q[group]]
        if self._gripper(group):
            return np.array([float(np.clip(1.0 - np.abs(q).sum() / FINGER_SPAN, 0.0, 1.0))])
        return q.copy()

    def qvel(self, data, group):
        self._check(group)
        v = data.qvel[self._v[group]]
        if self._gripper(group):  # the rate the inter-finger distance closes, per second of full travel
            return np.array([-float(np.sign(data.qpos[self._q[group]]) @ v) / FINGER_SPAN])
        return v.copy()

    def joint_qpos(self, data, group):
        self._check(group)
        return data.qpos[self._q[group]].copy()

    def joint_qvel(self, data, group):
        self._check(group)
        return data.qvel[self._v[group]].copy()

    def set_qpos(self, data, group, values):
        self._check(group)
        values = np.asarray(values, dtype=np.float64)
        if group == "base" and not values.size:  # the start pose (robot_base_pose)
            values = self._start
        if self._gripper(group):
            finger = GRIPPER_OPEN + float(np.clip(values[0], 0.0, 1.0)) * (GRIPPER_CLOSED - GRIPPER_OPEN)
            data.qpos[self._q[group]] = [finger, -finger]  # their coupling: finger 2 = -finger 1
        else:
            data.qpos[self._q[group]] = values
        data.qvel[self._v[group]] = 0.0
        self.command(data, group, values)

    def targets(self, data, group):
        self._check(group)
        ctrl = data.ctrl[self._u[group]]
        if self._gripper(group):
            return np.array([float((ctrl[0] - GRIPPER_OPEN) / (GRIPPER_CLOSED - GRIPPER_OPEN))])
        return ctrl.copy()

    def command_range(self, group):
        self._check(group)
        if self._gripper(group):
            return np.zeros(1), np.ones(1)
        lo, hi = self._lo[group], self._hi[group]
        return planar_base_range(lo, hi) if group == "base" else (lo.copy(), hi.copy())

    def command(self, data, group, values):
        self._check(group)
        values = np.array(values, dtype=np.float64)
        if self._gripper(group):
            values = GRIPPER_OPEN + np.clip(values[:1], 0.0, 1.0) * (GRIPPER_CLOSED - GRIPPER_OPEN)
        elif group == "base":  # their base group: the yaw target within ±π of the current yaw
            yaw = float(data.qpos[self._q["base"][2]])
            values[2] = yaw + (values[2] - yaw + math.pi) % (2 * math.pi) - math.pi
        data.ctrl[self._u[group]] = np.clip(values, self._lo[group], self._hi[group])

    def base_pose(self, data):
        return np.concatenate([data.xpos[self._base], data.xquat[self._base]])

    @property
    def tcp_site(self) -> int:
        return self._tcp

    @property
    def body_ids(self) -> frozenset[int]:
        return self._bodies


class RBY1(RobotType):
    """MolmoSpaces' RB-Y1 over their installed model; see the module docstring."""

    move_groups: ClassVar[dict[str, int]] = {"base": 3, "torso": 6, "left_arm": 7, "right_arm": 7,
                                             "left_gripper": 1, "right_gripper": 1}
    #: groups of their robot view that take no actions: held at ``init_qpos`` (their disabled head)
    held_groups: ClassVar[dict[str, int]] = {"head": 2}
    joint_names: ClassVar[dict[str, list[str]]] = {
        **{g: list(GROUPS[g][0]) for g in ("base", "torso", "left_arm", "right_arm")},
        "left_gripper": ["left_gripper"], "right_gripper": ["right_gripper"]}
    default_camera_system = "RBY1MjcfCameraSystem"
    #: their ``RBY1Config.init_qpos`` (grippers open, head 0.6 rad down); the base starts at robot_base_pose
    default_init_qpos: ClassVar[dict[str, list[float]]] = {
        "base": [], "torso": [0.0] * 6, "left_arm": [0.5, 0.0, 0.0, -2.3, 0.0, -0.5, 0.0],
        "right_arm": [0.5, 0.0, 0.0, -2.3, 0.0, -0.5, 0.0], "left_gripper": [GRIPPER_OPEN],
        "right_gripper": [GRIPPER_OPEN], "head": [0.0, 0.6]}

    def __init__(self, name: str, xml: str, assets_dir: str | None = None) -> None:
        self.name, self.xml, self.assets_dir = name, xml, assets_dir

    def configured(self, settings: object) -> RBY1:
        """This robot reading their model from the run's assets dir (``settings.assets_dir``)."""
        return RBY1(self.name, self.xml, getattr(settings, "assets_dir", None))

    def init_qpos(self, group: str, values: Sequence[float]) -> np.ndarray:
        """``base``: ``[]`` or three values, unused (module docstring); grippers: their finger-1 position
        (m, -0.05 open … 0 closed) or both finger positions, as 0 open … 1 closed; the rest as given."""
        if group == "base":
            if len(values) not in (0, 3):
                raise ValueError(f"expected [] or [x, y, yaw], got {len(values)} values")
            return np.zeros(0)
        if group.endswith("_gripper"):
            if len(values) not in (1, 2):
                raise ValueError(f"expected their finger-1 position or both finger positions (m), got {len(values)}")
            span = abs(float(values[0])) * 2 if len(values) == 1 else abs(float(values[0])) + abs(float(values[1]))
            if (len(values) == 1 and not GRIPPER_OPEN - 1e-6 <= values[0] <= 1e-6) or span > FINGER_SPAN + 1e-6:
                raise ValueError(f"finger positions {list(values)} outside their travel ({GRIPPER_OPEN} open … 0 m)")
            return np.array([float(np.clip(1.0 - span / FINGER_SPAN, 0.0, 1.0))])
        return super().init_qpos(group, values)

    def base_size(self, robot_spec: object) -> None:
        """The RB-Y1 stands on its own base: an episode's ``robot.base_size`` must be null or absent."""
        extra = getattr(robot_spec, "model_extra", None) or {}
        if extra.get("base_size") is not None:
            raise ValueError(f"robot.base_size: {self.name} has no pedestal, got {extra['base_size']!r}")

    def spec(self) -> mujoco.MjSpec:
        world = mujoco.MjSpec()
        self.add_to(world, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
        return world

    def add_to(self, world: mujoco.MjSpec, base_pose: Sequence[float],
               base_size: Sequence[float] | None = None) -> None:
        """Their model at the origin with the base actuators (module docstring); the base starts at ``base_pose``."""
        if base_size is not None:
            raise ValueError(f"robot.base_size: {self.name} has no pedestal, got {list(base_size)!r}")
        pose = self.base_pose(base_pose)
        yaw = _yaw(pose[3:])
        spec = load_model(self.name, self.xml, self.assets_dir)
        root = spec.body(ROOT_BODY)
        for body in root.find_all("body"):  # the bodies below the base, as their gravcomp override
            body.gravcomp = 1.0
        world.worldbody.add_frame(pos=[0.0, 0.0, INSERT_Z]).attach_body(root, "", "")
        world.worldbody.add_site(name=NAMESPACE + "world", pos=[0.0, 0.0, INSERT_Z])
        world.worldbody.add_site(name=START_SITE, pos=[pose[0], pose[1], INSERT_Z],
                                 quat=[math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)], group=5)
        for name, (limit, kp, damping, axis) in BASE_ACTUATORS.items():
            gear = [0.0] * 6
            gear[axis] = 1.0
            world.add_actuator(name=f"{NAMESPACE}{name}_act", target=NAMESPACE + "base_site",
                               refsite=NAMESPACE + "world", trntype=mujoco.mjtTrn.mjTRN_SITE, gear=gear,
                               ctrlrange=[-limit, limit], gaintype=mujoco.mjtGain.mjGAIN_FIXED,
                               biastype=mujoco.mjtBias.mjBIAS_AFFINE, gainprm=[kp] + [0.0] * 9,
                               biasprm=[0.0, -kp, damping] + [0.0] * 7)

    def bind(self, model: mujoco.MjModel) -> RBY1Handle:
        return RBY1Handle(model, self.name)


@hookimpl
def molmo_robots() -> list[RobotType]:
    return [RBY1("rby1", "rby1_site_control.xml"), RBY1("rby1m", "rby1_v1.2_site_control.xml")]
