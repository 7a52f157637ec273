"""Every task type's success check, ours against MolmoSpaces' own, on the same MuJoCo states.

One scene (:data:`SCENE_XML`: a table and a shelf, free objects of every primitive shape, a tray, a crate
and a plate as receptacles, two cabinets and a fridge with slides, limited and unlimited hinges, and a
two-finger gripper as the robot) is loaded from the same XML string in both venvs. Each task type gets
>= 200 states, sampled over the situations its rule tells apart plus states exactly at and 1e-6 either
side of every threshold; a state is a full ``qpos`` (and the force applied to the object, for pushes),
set with zero velocity and followed by ``mj_forward``. Episodes of several states check the rules that
remember (pick-and-place's carry-forward). Their verdict comes from their task class's
``judge_success`` (tests/parity/their_success.py), ours from our task plugin's ``success``.

Every state on which both MuJoCo versions find the same contacts must be judged alike, but for the
documented deliberate differences (docs/parity.md); where the contacts differ, the disagreements are
counted, not failed. docs/parity.md's agreement table is checked against the counts here.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from theirs import contact_table

from molmo_lerobot.benchmark.schema import EpisodeSpec
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.robots.base import RobotType
from molmo_lerobot.sim.env import Env, Timing
from molmo_lerobot.sim.geometry import subtree

pytestmark = pytest.mark.parity

TABLE_TOP = 0.40
APPLE = 0.025  # half size of the box "apple"
BALL = 0.03  # radius of the sphere "ball"
CAN_R, CAN_H = 0.03, 0.05  # radius and half height of the cylinder "can"
MARKER_R, MARKER_H = 0.012, 0.05  # capsule "marker"
TRAY_HALF, TRAY_FLOOR, TRAY_HEIGHT = 0.1, 0.01, 0.06
CRATE_HALF, CRATE_HEIGHT = 0.04, 0.06
PLATE_R, PLATE_HEIGHT = 0.08, 0.01
HAND_HOME = np.array([-0.9, 0.0, 1.0])  # the gripper's tool point with every slide at 0
PAD_Y, PAD_HALF_Y = 0.06, 0.005  # finger pad centre (open) and half thickness
PEN = 0.0005  # how far a resting body sinks into what carries it
IDENTITY = Rotation.identity()

SCENE_XML = f"""
<mujoco model="parity_success">
  <option timestep="0.002"/>
  <asset><material name="wood" rgba="0.6 0.4 0.2 1"/></asset>
  <worldbody>
    <geom name="floor" type="plane" size="4 4 0.1"/>
    <body name="table">
      <geom name="table_top" type="box" size="0.6 0.4 0.02" pos="0 0 {TABLE_TOP - 0.02}"/>
      <geom name="table_leg" type="box" size="0.03 0.03 0.18" pos="0.5 0.3 0.18"/>
    </body>
    <body name="shelf" pos="0 0.62 0">
      <geom name="shelf_top" type="box" size="0.3 0.2 0.02" pos="0 0 {TABLE_TOP - 0.02}"/>
    </body>
    <body name="robot/base" pos="-0.9 0 0">
      <geom name="robot/pedestal" type="box" size="0.1 0.1 0.2" pos="0 0 0.2"/>
      <body name="robot/hand" pos="0 0 1.0">
        <joint name="robot/x" type="slide" axis="1 0 0"/>
        <joint name="robot/y" type="slide" axis="0 1 0"/>
        <joint name="robot/z" type="slide" axis="0 0 1"/>
        <geom name="robot/palm" type="box" size="0.02 0.07 0.01" pos="0 0 0.06"/>
        <site name="robot/tcp"/>
        <body name="robot/left_finger">
          <joint name="robot/left" type="slide" axis="0 -1 0" range="0 0.055"/>
          <geom name="robot/left_pad" type="box" size="0.01 {PAD_HALF_Y} 0.015" pos="0 {PAD_Y} 0.005"/>
        </body>
        <body name="robot/right_finger">
          <joint name="robot/right" type="slide" axis="0 1 0" range="0 0.055"/>
          <geom name="robot/right_pad" type="box" size="0.01 {PAD_HALF_Y} 0.015" pos="0 -{PAD_Y} 0.005"/>
        </body>
      </body>
    </body>
    <body name="apple"><freejoint name="apple/free"/>
      <geom name="apple" type="box" size="{APPLE} {APPLE} {APPLE}" mass="0.2"/></body>
    <body name="ball"><freejoint name="ball/free"/>
      <geom name="ball" type="sphere" size="{BALL}" mass="0.1"/></body>
    <body name="can"><freejoint name="can/free"/>
      <geom name="can" type="cylinder" size="{CAN_R} {CAN_H}" mass="0.3"/></body>
    <body name="marker"><freejoint name="marker/free"/>
      <geom name="marker" type="capsule" size="{MARKER_R} {MARKER_H}" mass="0.05"/></body>
    <body name="ghost"><freejoint name="ghost/free"/>
      <geom name="ghost" type="box" size="0.02 0.02 0.02" group="3" mass="0.1"/></body>
    <body name="tray"><freejoint name="tray/free"/>
      <geom name="tray_floor" type="box" size="{TRAY_HALF} {TRAY_HALF} {TRAY_FLOOR / 2}"
            pos="0 0 {TRAY_FLOOR / 2}" mass="0.3"/>
      <geom name="tray_north" type="box" size="{TRAY_HALF} 0.005 0.025" pos="0 0.095 0.035" mass="0.05"
            material="wood"/>
      <geom name="tray_south" type="box" size="{TRAY_HALF} 0.005 0.025" pos="0 -0.095 0.035" mass="0.05"/>
      <geom name="tray_east" type="box" size="0.005 0.09 0.025" pos="0.095 0 0.035" mass="0.05"/>
      <geom name="tray_west" type="box" size="0.005 0.09 0.025" pos="-0.095 0 0.035" mass="0.05"/>
      <geom name="tray_collider" type="box" size="0.1 0.1 0.002" pos="0 0 -0.01" group="3" contype="0" conaffinity="0"/>
    </body>
    <body name="crate"><freejoint name="crate/free"/>
      <geom name="crate" type="box" size="{CRATE_HALF} {CRATE_HALF} {CRATE_HEIGHT / 2}"
            pos="0 0 {CRATE_HEIGHT / 2}" mass="0.5"/></body>
    <body name="plate"><freejoint name="plate/free"/>
      <geom name="plate" type="cylinder" size="{PLATE_R} {PLATE_HEIGHT / 2}"
            pos="0 0 {PLATE_HEIGHT / 2}" mass="0.2"/></body>
    <body name="cabinet" pos="1.5 0 0">
      <geom name="cabinet" type="box" size="0.2 0.3 0.4" pos="0 0 0.4" material="wood"/>
      <body name="cabinet/knob" pos="-0.21 0.2 0.7">
        <joint name="cabinet/knob_turn" type="hinge" axis="1 0 0"/>
        <geom type="cylinder" size="0.01 0.01" euler="0 1.5708 0" contype="0" conaffinity="0"/></body>
      <body name="cabinet/drawer" pos="-0.2 0 0.6">
        <joint name="cabinet/drawer_slide" type="slide" axis="-1 0 0" range="0 0.3"/>
        <geom type="box" size="0.18 0.25 0.08" pos="0.18 0 0" contype="0" conaffinity="0"/></body>
      <body name="cabinet/door" pos="-0.2 -0.3 0.25">
        <joint name="cabinet/door_hinge" type="hinge" axis="0 0 1" range="-1.57 0"/>
        <geom type="box" size="0.01 0.15 0.2" pos="0 0.15 0" contype="0" conaffinity="0"/></body>
    </body>
    <body name="cabinet2" pos="1.5 1.0 0">
      <geom name="cabinet2" type="box" size="0.2 0.3 0.4" pos="0 0 0.4"/>
      <body name="cabinet2/drawer" pos="-0.2 0 0.6">
        <joint name="cabinet2/drawer_slide" type="slide" axis="-1 0 0" range="0 0.25"/>
        <geom type="box" size="0.18 0.25 0.08" pos="0.18 0 0" contype="0" conaffinity="0"/></body>
      <body name="cabinet2/door" pos="-0.2 -0.3 0.25">
        <joint name="cabinet2/door_hinge" type="hinge" axis="0 0 1" range="0 1.2"/>
        <geom type="box" size="0.01 0.15 0.2" pos="0 0.15 0" contype="0" conaffinity="0"/></body>
      <body name="cabinet2/knob" pos="-0.21 0.2 0.7">
        <joint name="cabinet2/knob_turn" type="hinge" axis="1 0 0"/>
        <geom type="cylinder" size="0.01 0.01" euler="0 1.5708 0" contype="0" conaffinity="0"/></body>
    </body>
    <body name="fridge" pos="1.5 -1.0 0">
      <geom name="fridge" type="box" size="0.3 0.3 0.8" pos="0 0 0.8"/>
      <body name="fridge/door" pos="-0.3 -0.3 0.8">
        <joint name="fridge/door_hinge" type="hinge" axis="0 0 1" range="0 2.0"/>
        <geom type="box" size="0.01 0.3 0.8" pos="0 0.3 0" contype="0" conaffinity="0"/></body>
    </body>
  </worldbody>
</mujoco>
"""

METADATA = {"objects": {
    "table": {"category": "DiningTable"}, "shelf": {"category": "Shelf"}, "apple": {"category": "Apple"},
    "ball": {"category": "Ball"}, "can": {"category": "Can"}, "marker": {"category": "Pen"},
    "ghost": {"category": "Ghost"}, "tray": {"category": "Tray"}, "crate": {"category": "Box"},
    "plate": {"category": "Plate"},
    "cabinet": {"category": "Cabinet"}, "cabinet2": {"category": "Cabinet"}, "fridge": {"category": "Fridge"},
}}
FREE_BODIES = ("apple", "ball", "can", "marker", "ghost", "tray", "crate", "plate")
HALF_HEIGHT = {"apple": APPLE, "ball": BALL, "can": CAN_H, "marker": MARKER_H + MARKER_R, "ghost": 0.02}
HALF_WIDTH = {"apple": APPLE, "ball": BALL, "can": CAN_R, "marker": MARKER_R, "ghost": 0.02}
TASK_CLS = {
    "pick": "molmo_spaces.tasks.pick_task.PickTask",
    "pick_and_place": "molmo_spaces.tasks.pick_and_place_task.PickAndPlaceTask",
    "pick_and_place_next_to": "molmo_spaces.tasks.pick_and_place_next_to_task.PickAndPlaceNextToTask",
    "pick_and_place_color": "molmo_spaces.tasks.pick_and_place_color_task.PickAndPlaceColorTask",
    "open": "molmo_spaces.tasks.opening_tasks.OpeningTask",
    "close": "molmo_spaces.tasks.opening_tasks.OpeningTask",
}
EPS = 1e-6
MODEL = mujoco.MjModel.from_xml_string(SCENE_XML)


# States ------------------------------------------------------------------------------------------


def yaw_quat(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def quat(rot: Rotation) -> np.ndarray:
    return rot.as_quat(scalar_first=True)


class State:
    """A full ``qpos`` (every free body parked apart in the air, the gripper open and away, every
    articulated joint at 0) and the forces applied to bodies, edited by name."""

    def __init__(self) -> None:
        self.qpos = MODEL.qpos0.copy()
        self.xfrc = np.zeros((MODEL.nbody, 6))
        for i, name in enumerate(FREE_BODIES):
            self.place(name, [-2.0 + 0.5 * i, -2.5, 2.0])
        self.hand([-0.5, 0.0, 1.2], open_=True)

    def _adr(self, joint: str) -> int:
        return int(MODEL.jnt_qposadr[MODEL.joint(joint).id])

    def place(self, body: str, pos, q=(1.0, 0.0, 0.0, 0.0)) -> State:
        a = self._adr(f"{body}/free")
        self.qpos[a:a + 3], self.qpos[a + 3:a + 7] = pos, q
        return self

    def pose(self, body: str) -> np.ndarray:
        a = self._adr(f"{body}/free")
        return self.qpos[a:a + 7].copy()

    def joint(self, name: str, value: float) -> State:
        self.qpos[self._adr(name)] = value
        return self

    def hand(self, tcp, open_: bool = False, half_width: float = APPLE, left: bool = True,
             right: bool = True) -> State:
        """Tool point at ``tcp``; a closed finger's pad sinks 1 mm into a body ``half_width`` wide."""
        for axis, value in zip("xyz", np.asarray(tcp) - HAND_HOME, strict=True):
            self.joint(f"robot/{axis}", value)
        grip = PAD_Y - PAD_HALF_Y - half_width + 0.001
        self.joint("robot/left", 0.0 if open_ or not left else grip)
        self.joint("robot/right", 0.0 if open_ or not right else grip)
        return self

    def push(self, body: str, force) -> State:
        self.xfrc[MODEL.body(body).id, :3] = force
        return self

    def copy(self) -> State:
        return copy.deepcopy(self)


def resting_z(body: str) -> float:
    """Centre height of ``body`` (upright) resting on the table."""
    return TABLE_TOP + HALF_HEIGHT[body] - PEN


def in_frame(base_pose: np.ndarray, local_pos, local_rot: Rotation = IDENTITY):
    """World (pos, quat) of a pose given in the frame of ``base_pose`` (7 values)."""
    base = Rotation.from_quat(base_pose[3:], scalar_first=True)
    return base_pose[:3] + base.apply(local_pos), quat(base * local_rot)


def random_rotation(rng) -> Rotation:
    return Rotation.from_quat(rng.normal(size=4), scalar_first=True)


def case(cases: list, task: dict, kind: str, *states: State) -> None:
    cases.append({"task": task, "kind": kind, "states": list(states)})


def pick_cases(rng) -> list:
    """Lifted or not (start pose at, above or below the resting height), held by both fingers, one or
    none, touching the table or another object, at and either side of the lift threshold."""
    cases: list = []
    for i in range(240):
        obj = ["apple", "apple", "ball", "can"][i % 4]
        rest = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.25, 0.25), resting_z(obj)])
        start_z = rest[2] + rng.choice([0.0, 0.0, 0.01, -0.005])
        threshold = float(rng.choice([0.01, 0.01, 0.05, 0.0]))
        task = {"task_type": "pick", "pickup_obj_name": obj, "succ_pos_threshold": threshold,
                "pickup_obj_start_pose": [*rest[:2], start_z, 1.0, 0.0, 0.0, 0.0],
                "pickup_obj_goal_pose": [*rest[:2], start_z + 0.1, 1.0, 0.0, 0.0, 0.0]}
        kind = ["held", "held", "held_on_other", "floating", "resting_touched", "one_finger", "held_tilted"][i % 7]
        lift = rng.uniform(-0.01, 0.08) if kind != "resting_touched" else 0.0
        pos = np.array([rest[0], rest[1], rest[2] + lift])
        s = State()
        rot = Rotation.from_euler("y", rng.uniform(-0.6, 0.6)) if kind == "held_tilted" and obj == "apple" \
            else Rotation.identity()
        s.place(obj, pos, quat(rot))
        half = HALF_WIDTH[obj]
        if kind != "floating":
            s.hand(pos, half_width=half, right=kind != "one_finger")
        if kind == "held_on_other":  # the crate's side pressed against the object
            s.place("crate", [pos[0] + half + CRATE_HALF - 0.001, pos[1], pos[2] - CRATE_HEIGHT / 2])
        case(cases, task, kind, s)
    for threshold in (0.01, 0.05):  # the lift threshold: at it and either side
        for delta in (-EPS, 0.0, EPS):
            rest = np.array([0.1, 0.05, resting_z("apple")])
            task = {"task_type": "pick", "pickup_obj_name": "apple", "succ_pos_threshold": threshold,
                    "pickup_obj_start_pose": [*rest, 1.0, 0.0, 0.0, 0.0],
                    "pickup_obj_goal_pose": [*rest[:2], rest[2] + 0.1, 1.0, 0.0, 0.0, 0.0]}
            pos = rest + np.array([0, 0, threshold + delta])
            case(cases, task, "lift_boundary", State().place("apple", pos).hand(pos))
    return cases


TRAY_START = np.array([0.1, -0.15, TABLE_TOP - PEN, 1.0, 0.0, 0.0, 0.0])


def place_task(task_type: str, obj: str, receptacle: str, rng, **extra) -> dict:
    return {"task_type": task_type, "pickup_obj_name": obj, "place_receptacle_name": receptacle,
            "pickup_obj_start_pose": [0.3, 0.2, resting_z(obj), 1.0, 0.0, 0.0, 0.0],
            "place_receptacle_start_pose": TRAY_START.tolist() if receptacle == "tray" else
            [0.1, -0.15, TABLE_TOP - PEN, 1.0, 0.0, 0.0, 0.0],
            "receptacle_supported_weight_frac": float(rng.choice([0.5, 0.5, 0.9])),
            "max_place_receptacle_pos_displacement": float(rng.choice([0.1, 0.15])),
            "max_place_receptacle_rot_displacement": float(rng.choice([math.radians(45), math.radians(60)])),
            **extra}


def floor_height(receptacle: str) -> float:
    return {"tray": TRAY_FLOOR, "plate": PLATE_HEIGHT, "crate": CRATE_HEIGHT}[receptacle]


def receptacle_pose(task: dict, rng, moved: float | None = None, tilt: float = 0.0) -> np.ndarray:
    """The receptacle's pose: its start pose moved ``moved`` m in a random horizontal direction,
    turned about the vertical at random and tilted ``tilt`` rad about a random horizontal axis."""
    start = np.asarray(task["place_receptacle_start_pose"])
    moved = rng.uniform(0, 0.2) if moved is None else moved
    heading = rng.uniform(0, 2 * math.pi)
    axis = rng.uniform(0, 2 * math.pi)
    rot = Rotation.from_rotvec(tilt * np.array([math.cos(axis), math.sin(axis), 0.0])) * \
        Rotation.from_euler("z", rng.uniform(-math.pi, math.pi))
    pos = start[:3] + moved * np.array([math.cos(heading), math.sin(heading), 0.0])
    return np.concatenate([pos, quat(rot)])


def put(s: State, obj: str, rec: np.ndarray, receptacle: str, local_xy=(0.0, 0.0), lift: float = -PEN,
        local_rot: Rotation = IDENTITY) -> State:
    """``obj`` upright in ``receptacle`` (at pose ``rec``) at ``local_xy``, its base ``lift`` above the floor."""
    pos, q = in_frame(rec, [local_xy[0], local_xy[1], floor_height(receptacle) + HALF_HEIGHT[obj] + lift], local_rot)
    return s.place(obj, pos, q)


def lying_drop(obj: str) -> float:
    """A capsule lies on its side: its centre sits a radius (not a half length) above the floor."""
    return -(HALF_HEIGHT[obj] - MARKER_R) if obj == "marker" else 0.0


def pnp_cases(rng, task_type: str = "pick_and_place", receptacles=("tray",), colors: dict | None = None) -> list:
    """In the receptacle at rest, hovering (the contactless fallback's height band and the edge of the
    receptacle's box), on the table, held, pushed sideways, the receptacle moved, turned or tilted to
    and past its limits; carry-forward episodes lifting or turning a supported object by 5 mm / 10°
    and either side."""
    cases: list = []
    extra = {"object_colors": colors, "other_receptacle_names": [r for r in colors if r != "tray"]} if colors \
        else {}
    kinds = ["rest", "rest_moved", "tilted", "hover", "hover_edge", "on_table", "held", "pushed", "on_wall"]
    for i in range(230):
        receptacle = receptacles[i % len(receptacles)]
        obj = ["apple", "ball", "can", "marker", "ghost"][i % 5]
        task = place_task(task_type, obj, receptacle, rng, **extra)
        if colors:
            task["place_receptacle_name"] = receptacle
        kind = kinds[i % len(kinds)]
        s = State()
        rec = receptacle_pose(task, rng, moved=0.0 if kind not in ("rest_moved",) else None,
                              tilt=rng.uniform(0, 1.4) if kind == "tilted" else 0.0)
        s.place(receptacle, rec[:3], rec[3:])
        inner = (TRAY_HALF - 0.04) if receptacle == "tray" else 0.03
        xy = rng.uniform(-inner, inner, size=2)
        yaw = Rotation.from_euler("z", rng.uniform(-math.pi, math.pi))
        lying = Rotation.from_euler("y", math.pi / 2) if obj == "marker" else Rotation.identity()
        if kind in ("rest", "rest_moved", "tilted", "held", "pushed"):
            put(s, obj, rec, receptacle, xy, local_rot=yaw * lying, lift=-PEN + lying_drop(obj))
        elif kind == "hover":
            put(s, obj, rec, receptacle, xy, lift=rng.uniform(0.0, 0.07), local_rot=random_rotation(rng))
        elif kind == "hover_edge":  # the object's centre at the edge of the receptacle's box
            edge = {"tray": TRAY_HALF, "plate": PLATE_R, "crate": CRATE_HALF}[receptacle]
            put(s, obj, rec, receptacle, (edge + rng.uniform(-0.01, 0.01), 0.0), lift=0.03)
        elif kind == "on_table":
            s.place(obj, [rng.uniform(-0.4, -0.2), rng.uniform(0.1, 0.3), resting_z(obj)])
        elif kind == "on_wall" and receptacle == "tray":  # straddling the east wall's top
            put(s, obj, rec, receptacle, (0.095, xy[1]), lift=TRAY_HEIGHT - TRAY_FLOOR - PEN)
        else:
            put(s, obj, rec, receptacle, xy, lift=-PEN)
        if kind == "held":
            s.hand(s.pose(obj)[:3], half_width=HALF_WIDTH[obj])
        if kind == "pushed":
            weight = MODEL.body_subtreemass[MODEL.body(obj).id] * 9.81
            angle = rng.uniform(0, 1.0)
            s.push(obj, [weight * math.tan(angle), 0.0, 0.0])
        case(cases, task, kind, s)
    # The contactless fallback's height band: the object's base between half the tray's height below
    # its top and 1 cm above it (tray: floor top + 0.02 ... + 0.06), at and either side.
    for lift in (0.02, TRAY_HEIGHT):
        for delta in (-EPS, 0.0, EPS):
            task = place_task(task_type, "apple", "tray", rng, **extra)
            s = State().place("tray", TRAY_START[:3], TRAY_START[3:])
            put(s, "apple", TRAY_START, "tray", (0.0, 0.0), lift=lift + delta)
            case(cases, task, "fallback_band_boundary", s)
    # The receptacle's limits: moved / tilted exactly at them and either side (object resting in it).
    for delta in (-EPS, 0.0, EPS):
        task = place_task(task_type, "apple", "tray", rng, **extra)
        rec = receptacle_pose(task, rng, moved=task["max_place_receptacle_pos_displacement"] + delta)
        s = State().place("tray", rec[:3], rec[3:])
        case(cases, task, "moved_boundary", put(s, "apple", rec, "tray"))
        # a 20 degree limit: friction holds the object firmly, so only the tilt decides
        task = place_task(task_type, "apple", "tray", rng, **extra,
                          max_place_receptacle_rot_displacement=math.radians(20))
        rec = receptacle_pose(task, rng, moved=0.0, tilt=task["max_place_receptacle_rot_displacement"] + delta)
        s = State().place("tray", rec[:3], rec[3:])
        case(cases, task, "tilt_boundary", put(s, "apple", rec, "tray"))
    # Carry-forward: supported, then lifted from that pose (off the floor: no contact, below the
    # fallback's band) by 5 mm or turned by 10 degrees, at and either side; and away and back.
    for i, (lift, turn) in enumerate([(0.005 - EPS, 0.0), (0.005, 0.0), (0.005 + EPS, 0.0), (0.003, 0.0),
                                      (0.008, 0.0), (0.002, math.radians(10) - EPS),
                                      (0.002, math.radians(10) + EPS), (0.002, math.radians(5)),
                                      (0.002, math.radians(20))]):
        task = place_task(task_type, "apple", "tray", rng, **extra)
        xy = rng.uniform(-0.05, 0.05, size=2)
        base = State().place("tray", TRAY_START[:3], TRAY_START[3:])
        rest = put(base.copy(), "apple", TRAY_START, "tray", xy)
        up = put(base.copy(), "apple", TRAY_START, "tray", xy, lift=lift - PEN,
                 local_rot=Rotation.from_euler("z", turn))
        case(cases, task, "carry_forward", rest, up)
        if i == 0:
            away = base.copy().place("apple", [-0.3, 0.2, resting_z("apple")])
            case(cases, task, "carry_forward_away_and_back", rest, away, up)
            case(cases, task, "carry_forward_never_supported", away, up)
    return cases


CRATE_START = np.array([0.15, 0.1, TABLE_TOP - PEN, 1.0, 0.0, 0.0, 0.0])


def next_to_cases(rng) -> list:
    """Beside the crate at gaps across [min, max + 1 cm] and past, exactly at both ends and either side;
    on another surface (the shelf), on the crate, hovering, held; the crate moved or turned to and past
    its limits."""
    cases: list = []
    kinds = ["beside", "beside", "beside", "crate_moved", "crate_turned", "on_shelf", "on_crate", "hover",
             "held_low", "held_high"]
    for i in range(220):
        obj = ["apple", "apple", "ball", "can", "ghost", "apple", "ball"][i % 7]
        task = {"task_type": "pick_and_place_next_to", "pickup_obj_name": obj, "place_receptacle_name": "crate",
                "pickup_obj_start_pose": [0.3, -0.2, resting_z(obj), 1.0, 0.0, 0.0, 0.0],
                "place_receptacle_start_pose": CRATE_START.tolist(),
                "min_surface_to_surface_gap": float(rng.choice([0.0, 0.0, 0.02])),
                "max_surface_to_surface_gap": float(rng.choice([0.05, 0.08])),
                "max_place_receptacle_pos_displacement": float(rng.choice([0.05, 0.1])),
                "max_place_receptacle_rot_displacement": float(rng.choice([math.radians(45), math.radians(30)]))}
        kind = kinds[i % len(kinds)]
        s = State()
        crate = CRATE_START.copy()
        if kind == "crate_moved":
            heading = rng.uniform(0, 2 * math.pi)
            crate[:2] += rng.uniform(0, 0.15) * np.array([math.cos(heading), math.sin(heading)])
        if kind == "crate_turned":
            crate[3:] = yaw_quat(rng.uniform(-1.2, 1.2))
        if kind == "on_shelf":  # crate at the table's edge, the object across the 2 cm slot on the shelf
            crate[:2] = [0.0, 0.4 - CRATE_HALF - rng.uniform(0.0, 0.01)]
        s.place("crate", crate[:3], crate[3:])
        half = HALF_WIDTH[obj]
        gx, gy = rng.uniform(-0.06, 0.12), rng.uniform(-0.06, 0.12)
        if max(gx, gy) < 0.002:
            gx = 0.002 + rng.uniform(0, 0.1)
        sx, sy = rng.choice([-1, 1], size=2)
        pos = np.array([crate[0] + sx * (CRATE_HALF + half + gx), crate[1] + sy * (CRATE_HALF + half + gy),
                        resting_z(obj)])
        if kind == "on_shelf":
            pos[:2] = [rng.uniform(-0.1, 0.1), 0.42 + half + rng.uniform(0.0, 0.03)]
        elif kind == "on_crate":
            pos = np.array([crate[0], crate[1], TABLE_TOP - PEN + CRATE_HEIGHT + HALF_HEIGHT[obj] - PEN])
        elif kind == "hover":
            pos[2] += rng.uniform(0.0, 0.04)
        elif kind in ("held_low", "held_high"):
            pos[2] += 0.01 if kind == "held_low" else 0.05
            s.hand(pos, half_width=half)
        s.place(obj, pos)
        case(cases, task, kind, s)
    for gap_name in ("min", "max"):  # the gap's ends (max + 1 cm tolerance), at them and either side
        for delta in (-EPS, 0.0, EPS):
            task = {"task_type": "pick_and_place_next_to", "pickup_obj_name": "apple",
                    "place_receptacle_name": "crate", "place_receptacle_start_pose": CRATE_START.tolist(),
                    "pickup_obj_start_pose": [0.3, -0.2, resting_z("apple"), 1.0, 0.0, 0.0, 0.0],
                    "min_surface_to_surface_gap": 0.02, "max_surface_to_surface_gap": 0.05,
                    "max_place_receptacle_pos_displacement": 0.05,
                    "max_place_receptacle_rot_displacement": math.radians(45)}
            gap = (0.02 if gap_name == "min" else 0.06) + delta
            s = State().place("crate", CRATE_START[:3], CRATE_START[3:])
            s.place("apple", [CRATE_START[0] + CRATE_HALF + APPLE + gap, CRATE_START[1], resting_z("apple")])
            case(cases, task, f"gap_{gap_name}_boundary", s)
    for limit in ("moved", "turned"):  # the crate's limits, at them and either side
        for delta in (-EPS, 0.0, EPS):
            task = {"task_type": "pick_and_place_next_to", "pickup_obj_name": "apple",
                    "place_receptacle_name": "crate", "place_receptacle_start_pose": CRATE_START.tolist(),
                    "pickup_obj_start_pose": [0.3, -0.2, resting_z("apple"), 1.0, 0.0, 0.0, 0.0],
                    "min_surface_to_surface_gap": 0.0, "max_surface_to_surface_gap": 0.05,
                    "max_place_receptacle_pos_displacement": 0.05,
                    "max_place_receptacle_rot_displacement": math.radians(45)}
            crate = CRATE_START.copy()
            if limit == "moved":
                crate[1] += 0.05 + delta
            else:
                crate[3:] = yaw_quat(math.radians(45) + delta)
            s = State().place("crate", crate[:3], crate[3:])
            s.place("apple", [crate[0] - 0.12, crate[1], resting_z("apple")])
            case(cases, task, f"crate_{limit}_boundary", s)
    return cases


ARTICULATED = {  # object -> its limited joints (name, range) in model order; knobs are unlimited
    "cabinet": [("cabinet/drawer_slide", (0.0, 0.3)), ("cabinet/door_hinge", (-1.57, 0.0))],
    "cabinet2": [("cabinet2/drawer_slide", (0.0, 0.25)), ("cabinet2/door_hinge", (0.0, 1.2))],
    "fridge": [("fridge/door_hinge", (0.0, 2.0))],
}
KNOBS = ("cabinet/knob_turn", "cabinet2/knob_turn")


def articulated_state(rng, spread: float) -> State:
    """Every articulated joint at a random opening, ``spread`` of the time; else closed."""
    s = State()
    for joints in ARTICULATED.values():
        for name, (lo, hi) in joints:
            s.joint(name, rng.uniform(lo, hi) if rng.uniform() < spread else 0.0)
    for knob in KNOBS:
        s.joint(knob, 0.0 if rng.uniform() < 0.5 else rng.uniform(-3, 3))
    return s


def open_close_cases(rng, mode: str) -> list:
    """Random openings of every joint judged with each object, joint, joint index, threshold and
    (open) ``any_inst_of_category``; the judged joint exactly at the threshold and either side."""
    cases: list = []
    for i in range(220):
        obj = ["cabinet", "cabinet2", "fridge"][i % 3]
        joint, _ = ARTICULATED[obj][int(rng.integers(len(ARTICULATED[obj])))]
        task = opening_task(mode, obj, joint, joint_index=int(rng.integers(3 if obj != "fridge" else 1)),
                            task_success_threshold=float(rng.choice([0.2, 0.2, 0.5, 0.9])),
                            any_inst_of_category=bool(mode == "open" and rng.uniform() < 0.4))
        case(cases, task, "random", articulated_state(rng, spread=float(rng.choice([0.3, 1.0]))))
    for obj, index in (("cabinet", 1), ("cabinet", 2), ("cabinet2", 0), ("cabinet2", 1), ("fridge", 0)):
        joints = [("cabinet/knob_turn", (0, 0))] + ARTICULATED["cabinet"] if obj == "cabinet" else \
            ARTICULATED[obj] + ([("cabinet2/knob_turn", (0, 0))] if obj == "cabinet2" else [])
        name, (lo, hi) = joints[index]
        for threshold in (0.2, 0.5):
            for delta in (-EPS, 0.0, EPS):
                fraction = threshold if mode == "open" else 1.0 - threshold
                value = (fraction + delta) * (hi - lo) * (1 if hi > 0 else -1)
                task = opening_task(mode, obj, name, joint_index=index, task_success_threshold=threshold,
                                    any_inst_of_category=False)
                s = State().joint(name, value)
                if obj == "cabinet":
                    s.joint("cabinet/knob_turn", 0.1)
                case(cases, task, "threshold_boundary", s)
    return cases


#: the first cell of each family's row in docs/parity.md's success-check table
TABLE_ROWS = {family: family for family in ("pick", "pick_and_place", "pick_and_place_next_to",
                                            "pick_and_place_color", "open", "close")}
FAMILIES = {
    "pick": pick_cases,
    "pick_and_place": pnp_cases,
    "pick_and_place_next_to": next_to_cases,
    "pick_and_place_color": lambda rng: pnp_cases(rng, "pick_and_place_color", receptacles=("tray", "plate"),
                                                  colors={"tray": [1.0, 0.0, 0.0, 1.0], "plate": [0.0, 0.0, 1.0, 1.0]}),
    "open": lambda rng: open_close_cases(rng, "open"),
    "close": lambda rng: open_close_cases(rng, "close"),
}


# Both sides --------------------------------------------------------------------------------------


def episode_spec(task: dict, plugins: Plugins) -> EpisodeSpec:
    fields = {k: v for k, v in task.items() if v is not None}
    return parse_episode({
        "house_index": 0, "scene_dataset": "parity_scene", "seed": 0, "img_resolution": [64, 64],
        "language": {"task_description": "parity"},
        "robot": {"robot_name": "parity_gripper", "init_qpos": {}},
        "task": {"task_cls": TASK_CLS[task["task_type"]], "robot_base_pose": [0, 0, 0, 1, 0, 0, 0], **fields}}, plugins)


def opening_task(mode: str, obj: str, joint: str, **fields) -> dict:
    return {"task_type": mode, "pickup_obj_name": obj, "joint_name": joint, "joint_start_position": 0.0,
            "pickup_obj_start_pose": [1.5, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0], **fields}


#: our Env needs from its robot only the bodies it is made of (the contact tests) and its base pose check
GRIPPER = SimpleNamespace(bind=lambda model: SimpleNamespace(body_ids=subtree(model, model.body("robot/base").id)),
                          move_groups={}, joint_names={}, base_pose=RobotType.base_pose)


def ours(cases: list) -> tuple[list[bool], list[np.ndarray]]:
    """Our verdict and contact table (``theirs.contact_table``) for every state, a fresh task per case."""
    plugins = Plugins()
    verdicts, contacts = [], []
    for c in cases:
        spec = episode_spec(c["task"], plugins)
        env = Env(spec, Timing(), copy.copy(MODEL), GRIPPER, [])
        env._scene_metadata = METADATA  # what our scene datasets give an episode
        task = plugins.task_type(spec.task_name).create(spec, env)
        task.setup()
        for s in c["states"]:
            env.data.qpos[:], env.data.qvel[:], env.data.xfrc_applied[:] = s.qpos, 0.0, s.xfrc
            mujoco.mj_forward(env.model, env.data)
            verdicts.append(bool(task.success()))
            contacts.append(contact_table(env.model, env.data))
    return verdicts, contacts


def theirs_inputs(cases: list) -> dict:
    states = [s for c in cases for s in c["states"]]
    episodes, first = [], 0
    for c in cases:
        episodes.append({"task": c["task"], "first": first, "count": len(c["states"])})
        first += len(c["states"])
    return {"xml": SCENE_XML, "metadata": METADATA, "robot_root": "robot/base", "robot_namespace": "robot/",
            "episodes": episodes, "qpos": np.array([s.qpos for s in states]),
            "xfrc": np.array([s.xfrc for s in states])}


def nan_first(task: dict, state: State) -> bool:
    """Whether MolmoSpaces' open check is NaN, so False, on ``state``: the first joint its opening list
    takes (objects by name, joints in model order, free joints and turned zero-range joints skipped) is
    an unlimited joint (range 0..0) at exactly 0, and ``max`` keeps a NaN it meets first."""
    if task["task_type"] != "open":
        return False
    category = METADATA["objects"][task["pickup_obj_name"]]["category"]
    objects = sorted(o for o in ARTICULATED if METADATA["objects"][o]["category"] == category) \
        if task["any_inst_of_category"] else [task["pickup_obj_name"]]
    for obj in objects:
        for j in range(MODEL.njnt):
            if MODEL.body_rootid[MODEL.jnt_bodyid[j]] != MODEL.body(obj).id:
                continue
            span, q = abs(MODEL.jnt_range[j, 1] - MODEL.jnt_range[j, 0]), state.qpos[MODEL.jnt_qposadr[j]]
            if span == 0 and q != 0:
                continue  # inf: skipped there
            return bool(span == 0)
    return False


@dataclass
class Comparison:
    """One family's states judged on both sides."""

    kinds: list[str]  # the case kind of each state
    ours: list[bool]
    theirs: list[bool]
    same_contacts: list[bool]  # MuJoCo 3.5 (theirs) and ours found the same contacts and forces
    deliberate: list[bool]  # a documented deliberate difference predicts their verdict differs

    @property
    def agreed(self) -> int:
        return sum(o == t for o, t in zip(self.ours, self.theirs, strict=True))

    def disagreements(self, same_contacts: bool) -> dict[str, int]:
        """Disagreeing states by kind, among states whose contacts are (or are not) the same."""
        out: dict[str, int] = {}
        for kind, o, t, same, deliberate in zip(self.kinds, self.ours, self.theirs, self.same_contacts,
                                               self.deliberate, strict=True):
            if o != t and same == same_contacts and not deliberate:
                out[kind] = out.get(kind, 0) + 1
        return out


@pytest.fixture(scope="module")
def comparisons(theirs) -> dict[str, Comparison]:
    """Every family's cases judged on both sides (one call in the parity venv for all of them)."""
    rng = np.random.default_rng(20251124)
    cases = {family: make(rng) for family, make in FAMILIES.items()}
    got = theirs.run("their_success:judge", theirs_inputs([c for family in FAMILIES for c in cases[family]]))
    out, start = {}, 0
    for family in FAMILIES:
        states = [(c, s) for c in cases[family] for s in c["states"]]
        mine, my_contacts = ours(cases[family])
        their = [bool(v) for v in got["success"][start:start + len(states)]]
        same = [theirs.same_contacts(a, b) for a, b in zip(my_contacts, got["contacts"][start:start + len(states)],
                                                             strict=True)]
        out[family] = Comparison([c["kind"] for c, _ in states], mine, their, same,
                                 [nan_first(c["task"], s) and m and not t
                                  for (c, s), m, t in zip(states, mine, their, strict=True)])
        start += len(states)
    return out


@pytest.mark.parametrize("family", list(FAMILIES))
def test_success_check_agrees_with_molmospaces(comparisons, family, theirs):
    """Every state on which both MuJoCo versions find the same contacts is judged alike, but for the
    documented deliberate differences; the counts are docs/parity.md's."""
    c = comparisons[family]
    assert len(c.kinds) >= 200
    for kind in {k for k in c.kinds if k.endswith("_boundary")}:  # each threshold is really straddled
        assert {o for k, o in zip(c.kinds, c.ours, strict=True) if k == kind} == {True, False}, kind
    assert not c.disagreements(same_contacts=True), f"{family}: rule disagreements by kind: {c.disagreements(True)}"
    row = theirs.table_row(TABLE_ROWS[family])
    reported = {"cases": len(c.kinds), "agreed": c.agreed, "same contacts": sum(c.same_contacts),
                "deliberate": sum(c.deliberate), "contacts differ, judged differently":
                sum(o != t and not s for o, t, s in zip(c.ours, c.theirs, c.same_contacts, strict=True))}
    assert row == reported, f"docs/parity.md's row for {family} is out of date: it should read {reported}"


PAINTABLE = ("tray", "crate", "plate", "apple", "ghost", "cabinet", "fridge")


def test_colours_are_painted_as_molmospaces_paints_them(theirs):
    """pick_and_place_color: every geom's rgba and material after painting ``object_colors`` equal their
    JSON evaluation's (visible geoms of each body's subtree, material cleared), for random colourings."""
    rng = np.random.default_rng(7)
    colorings = [{name: [float(v) for v in rng.uniform(0, 1, 4).round(3)]
                  for name in rng.choice(PAINTABLE, size=int(rng.integers(1, 4)), replace=False)} for _ in range(24)]
    got = theirs.run("their_success:paint", {**theirs_inputs([]), "colorings": colorings})
    plugins = Plugins()
    agreed = 0
    for colors, rgba, matid in zip(colorings, got["rgba"], got["matid"], strict=True):
        task = place_task("pick_and_place_color", "apple", "tray", rng, object_colors=colors)
        spec = episode_spec(task, plugins)
        env = Env(spec, Timing(), copy.copy(MODEL), GRIPPER, [])
        plugins.task_type(spec.task_name).create(spec, env)
        agreed += bool(np.array_equal(env.model.geom_rgba, rgba) and np.array_equal(env.model.geom_matid, matid))
    assert theirs.table_row("colour painting") == {"cases": len(colorings), "agreed": agreed}
    assert agreed == len(colorings)
