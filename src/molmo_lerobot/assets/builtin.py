"""The built-in object set: graspable primitives (blocks, cans, mugs, balls …) and their analytic grasps.

Every object is one MuJoCo primitive geom on one free body, sized for the Franka hand
(at most :data:`MAX_GRASP_WIDTH` across the grasped dimension). Grasps are poses of the
gripper TCP in the object frame (MolmoSpaces' unified convention): origin at the gripping
centre between the finger pads, ``+z`` the approach direction (palm → fingertips), ``+y`` the
finger opening/closing axis. Where the TCP sits along the approach depends on the object's
size and the hand's reach (:class:`HandGeometry`), so the analytic grasps are computed per hand.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class HandGeometry:
    """A parallel-jaw hand seen from its TCP, in metres along the approach / finger axes."""

    #: TCP to the fingertips (the farthest they reach while closing)
    tcp_to_fingertip: float
    #: palm (where an object stops between the fingers) to the TCP
    palm_to_tcp: float
    #: widest object dimension the hand grasps reliably
    max_grasp_width: float
    #: half the finger pad width along the TCP x axis; grasps keep the pads on the object
    pad_half_width: float
    #: half the open hand's span along the finger axis, fingers included
    open_half_span: float


#: the Panda hand of ``franka`` (gymnasium-robotics): long fingers, the TCP mid-way along them
PANDA_HAND = HandGeometry(tcp_to_fingertip=0.035, palm_to_tcp=0.058, max_grasp_width=0.07, pad_half_width=0.01,
                          open_half_span=0.052)
#: the Robotiq 2F-85 of ``franka_droid``: the TCP is the pinch point (pads' centre, fingers closed);
#: closing swings the pads 1.4 cm forward, so the fingertips end 1.8 cm beyond it
ROBOTIQ_2F85 = HandGeometry(tcp_to_fingertip=0.018, palm_to_tcp=0.054, max_grasp_width=0.075, pad_half_width=0.01,
                            open_half_span=0.06)
#: hand name (``RobotType.hand``) -> the geometry the built-in grasp library computes its analytic grasps
#: for; a robot states its own hand's geometry (``RobotType.hand_geometry``)
HANDS: dict[str, HandGeometry] = {"franka": PANDA_HAND, "franka_droid": ROBOTIQ_2F85}

#: widest object dimension a built-in object may have across a grasped dimension (the Panda's limit)
MAX_GRASP_WIDTH = PANDA_HAND.max_grasp_width
#: clearance kept between the fingertips / palm and the object's far / near side
FINGERTIP_CLEARANCE = 0.005
#: how far the fingertips reach into an object with flat gripped faces at the least
MIN_FLAT_GRIP = 0.03

SHAPES = ("box", "cylinder", "sphere", "capsule")


@dataclass(frozen=True)
class BuiltinObject:
    """A primitive object: one free body named ``uid`` holding one geom."""

    uid: str
    category: str
    shape: str  # "box" | "cylinder" | "sphere" | "capsule"
    size: tuple[float, ...]  # MuJoCo geom size convention (half sizes)
    rgba: tuple[float, float, float, float]
    mass: float
    description: str
    synset: str

    def __post_init__(self) -> None:
        expected = {"box": 3, "cylinder": 2, "sphere": 1, "capsule": 2}
        if self.shape not in expected:
            raise ValueError(f"object {self.uid!r}: shape {self.shape!r} is not one of {SHAPES}")
        if len(self.size) != expected[self.shape] or min(self.size) <= 0:
            raise ValueError(f"object {self.uid!r}: {self.shape} needs {expected[self.shape]} positive sizes, "
                             f"got {self.size}")

    @property
    def half_extents(self) -> tuple[float, float, float]:
        """Half extents of the axis-aligned bounding box in the object frame."""
        s = self.size
        if self.shape == "box":
            return (s[0], s[1], s[2])
        if self.shape == "cylinder":
            return (s[0], s[0], s[1])
        if self.shape == "sphere":
            return (s[0], s[0], s[0])
        return (s[0], s[0], s[1] + s[0])  # capsule: radius, half-length of the segment

    @property
    def color(self) -> str:
        """The colour word of the description (first word)."""
        return self.description.split()[0]

    def metadata(self) -> dict:
        """The asset-library metadata document (MolmoSpaces' fields)."""
        return _metadata_doc(self, f"{self.shape} primitive")

    def mjcf(self) -> str:
        """A standalone MJCF document: one free body ``uid`` with its geom."""
        size = " ".join(f"{v:g}" for v in self.size)
        rgba = " ".join(f"{v:g}" for v in self.rgba)
        # condim 6 adds torsional and rolling friction so round objects do not roll away
        return (
            f'<mujoco model="{self.uid}">\n'
            "  <worldbody>\n"
            f'    <body name="{self.uid}">\n'
            f'      <freejoint name="{self.uid}_free"/>\n'
            f'      <geom name="{self.uid}_geom" type="{self.shape}" size="{size}" rgba="{rgba}" '
            f'mass="{self.mass:g}" friction="1.0 0.01 0.001" condim="6" contype="1" conaffinity="1"/>\n'
            "    </body>\n"
            "  </worldbody>\n"
            "</mujoco>\n"
        )


def _obj(uid, category, shape, size, rgba, mass, description, synset) -> tuple[str, BuiltinObject]:
    return uid, BuiltinObject(uid, category, shape, tuple(size), tuple(rgba), mass, description, synset)


RED = (0.85, 0.12, 0.1, 1.0)
GREEN = (0.15, 0.7, 0.2, 1.0)
BLUE = (0.12, 0.3, 0.85, 1.0)
YELLOW = (0.95, 0.85, 0.1, 1.0)
ORANGE = (1.0, 0.5, 0.05, 1.0)
PURPLE = (0.55, 0.2, 0.7, 1.0)
WHITE = (0.92, 0.92, 0.9, 1.0)
GREY = (0.6, 0.62, 0.65, 1.0)

BUILTIN_OBJECTS: dict[str, BuiltinObject] = dict(
    [
        _obj("builtin_red_block", "block", "box", (0.025, 0.025, 0.025), RED, 0.08, "red wooden block", "block.n.01"),
        _obj("builtin_green_block", "block", "box", (0.022, 0.022, 0.022), GREEN, 0.06, "green wooden block",
             "block.n.01"),
        _obj("builtin_blue_block", "block", "box", (0.027, 0.027, 0.027), BLUE, 0.1, "blue wooden block", "block.n.01"),
        _obj("builtin_yellow_brick", "brick", "box", (0.02, 0.045, 0.025), YELLOW, 0.09, "yellow toy brick",
             "brick.n.01"),
        _obj("builtin_red_can", "can", "cylinder", (0.03, 0.055), RED, 0.15, "red soda can", "can.n.01"),
        _obj("builtin_grey_can", "can", "cylinder", (0.032, 0.04), GREY, 0.2, "grey tin can", "can.n.01"),
        _obj("builtin_red_mug", "mug", "cylinder", (0.034, 0.045), RED, 0.15, "red ceramic mug", "mug.n.04"),
        _obj("builtin_blue_mug", "mug", "cylinder", (0.034, 0.045), BLUE, 0.15, "blue ceramic mug", "mug.n.04"),
        _obj("builtin_white_cup", "cup", "cylinder", (0.029, 0.05), WHITE, 0.05, "white paper cup", "cup.n.01"),
        _obj("builtin_green_bottle", "bottle", "cylinder", (0.03, 0.08), GREEN, 0.2, "green plastic bottle",
             "bottle.n.01"),
        _obj("builtin_yellow_ball", "ball", "sphere", (0.032,), YELLOW, 0.06, "yellow tennis ball", "tennis_ball.n.01"),
        _obj("builtin_orange", "fruit", "sphere", (0.034,), ORANGE, 0.13, "orange fruit", "orange.n.01"),
        _obj("builtin_purple_marker", "marker", "capsule", (0.015, 0.05), PURPLE, 0.04, "purple felt marker",
             "marker.n.03"),
    ]
)


def _pose(approach: np.ndarray, finger: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """A 4x4 TCP pose with ``+z = approach`` and ``+y = finger`` (made orthogonal) at ``pos``."""
    z = approach / np.linalg.norm(approach)
    y = finger - np.dot(finger, z) * z
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, pos
    return T


def _depth(half: float, hand: HandGeometry, flat: bool = False) -> float | None:
    """TCP offset along the approach from the centre, or None when the pads cannot reach the object.

    The TCP sits at the centre unless that would push the fingertips past the far side or
    the palm into the near side. The pads must still reach the object's mid-plane, or, where
    the gripped faces run straight along the approach (``flat``: box faces, a cylinder's wall
    seen from its end), reach :data:`MIN_FLAT_GRIP` into the object.
    """
    tip, palm, gap = hand.tcp_to_fingertip, hand.palm_to_tcp, FINGERTIP_CLEARANCE
    s = min(0.0, half - tip - gap, palm - gap - half)
    reach = s + tip - gap if not flat else s + tip + half - MIN_FLAT_GRIP
    return s if reach >= 0 else None


def _perpendicular(v: np.ndarray) -> np.ndarray:
    helper = np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    p = np.cross(v, helper)
    return p / np.linalg.norm(p)


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues rotation of ``v`` about unit ``axis``."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * np.dot(axis, v) * (1 - c)


def _box_grasps(half: np.ndarray, hand: HandGeometry) -> list[np.ndarray]:
    out = []
    for k in range(3):  # face normal axis; the palm is outside that face
        s = _depth(half[k], hand, flat=True)
        if s is None:
            continue
        for sign in (1.0, -1.0):
            approach = np.zeros(3)
            approach[k] = -sign
            for j in range(3):
                if j == k or 2 * half[j] > hand.max_grasp_width:
                    continue
                m = 3 - k - j  # the axis along the finger width
                if half[m] < hand.pad_half_width:
                    continue
                for fs in (1.0, -1.0):
                    finger = np.zeros(3)
                    finger[j] = fs
                    out.append(_pose(approach, finger, s * approach))
    return out


def _round_side_grasps(radius: float, half_len: float, n_azimuth: int, n_along: int,
                       hand: HandGeometry) -> list[np.ndarray]:
    """Approach perpendicular to the local z axis, fingers closing across the diameter."""
    if 2 * radius > hand.max_grasp_width:
        return []
    s = _depth(radius, hand)
    if s is None:
        return []
    reach = max(0.0, half_len - hand.pad_half_width)
    offsets = np.linspace(-reach, reach, n_along) if n_along > 1 and reach > 0 else np.zeros(1)
    out = []
    for phi in np.arange(n_azimuth) * 2 * np.pi / n_azimuth:
        approach = np.array([np.cos(phi), np.sin(phi), 0.0])
        finger = np.cross([0.0, 0.0, 1.0], approach)
        for t in offsets:
            for fs in (1.0, -1.0):
                out.append(_pose(approach, fs * finger, s * approach + np.array([0.0, 0.0, t])))
    return out


def _round_end_grasps(radius: float, half_height: float, n_yaw: int, hand: HandGeometry) -> list[np.ndarray]:
    """Approach along ±z (top-down when upright), fingers at ``n_yaw`` yaws."""
    if 2 * radius > hand.max_grasp_width:
        return []
    s = _depth(half_height, hand, flat=True)
    if s is None:
        return []
    out = []
    for sign in (1.0, -1.0):
        approach = np.array([0.0, 0.0, -sign])
        for yaw in np.arange(n_yaw) * 2 * np.pi / n_yaw:
            finger = np.array([np.cos(yaw), np.sin(yaw), 0.0])
            out.append(_pose(approach, finger, s * approach))
    return out


def _sphere_grasps(radius: float, hand: HandGeometry) -> list[np.ndarray]:
    if 2 * radius > hand.max_grasp_width:
        return []
    s = _depth(radius, hand)
    if s is None:
        return []
    dirs = [np.eye(3)[i] * sg for i in range(3) for sg in (1.0, -1.0)]
    dirs += [np.array([a, b, c]) / np.sqrt(3) for a in (1, -1) for b in (1, -1) for c in (1, -1)]
    out = []
    for approach in dirs:
        base = _perpendicular(approach)
        for roll in np.arange(4) * np.pi / 4:
            out.append(_pose(approach, _rotate(base, approach, roll), s * approach))
    return out


def analytic_grasps(obj: BuiltinObject, hand: HandGeometry = PANDA_HAND) -> np.ndarray:
    """Grasp poses ``(N, 4, 4)`` of ``hand``'s TCP in ``obj``'s frame (see the module docstring)."""
    if obj.shape == "box":
        grasps = _box_grasps(np.asarray(obj.size, dtype=float), hand)
    elif obj.shape == "cylinder":
        r, hh = obj.size
        grasps = _round_end_grasps(r, hh, 8, hand) + _round_side_grasps(r, hh, 8, 3, hand)
    elif obj.shape == "sphere":
        grasps = _sphere_grasps(obj.size[0], hand)
    else:  # capsule: the ends are hemispheres, so the end grasps see radius + half-length
        r, hl = obj.size
        grasps = _round_end_grasps(r, hl + r, 8, hand) + _round_side_grasps(r, hl, 8, 3, hand)
    if not grasps:
        raise ValueError(f"object {obj.uid!r}: no grasp fits a {hand.max_grasp_width} m wide gripper")
    return np.stack(grasps).astype(np.float64)


# Receptacles ---------------------------------------------------------------------------------

RECEPTACLE_SHAPES = ("bowl", "plate", "tray", "box")


#: ``(suffix, type, size, pos, yaw)`` of one geom of a receptacle, in its body frame
ReceptacleGeom = tuple[str, str, tuple[float, ...], tuple[float, float, float], float]


@dataclass(frozen=True)
class BuiltinReceptacle:
    """A receptacle: one free body ``uid`` with a base geom and a ring of rim geoms.

    ``shape`` is ``"bowl"`` / ``"plate"`` (round base, rim of ``RIM_SEGMENTS`` boxes) or
    ``"tray"`` / ``"box"`` (rectangular base, four walls). ``half_size`` is the outer half
    extent (x, y) of the footprint (radius twice for round ones), ``base_half_height`` the
    half thickness of the base and ``rim_height`` the wall height above the base.
    Receptacles are never grasped, so they have no grasps.
    """

    uid: str
    category: str
    shape: str
    half_size: tuple[float, float]
    base_half_height: float
    rim_height: float
    rgba: tuple[float, float, float, float]
    mass: float
    description: str
    synset: str
    receptacle: bool = True

    #: wall thickness, and the number of rim segments of round receptacles
    WALL = 0.005
    RIM_SEGMENTS = 16

    def __post_init__(self) -> None:
        if self.shape not in RECEPTACLE_SHAPES:
            raise ValueError(f"receptacle {self.uid!r}: shape {self.shape!r} is not one of {RECEPTACLE_SHAPES}")
        if min(*self.half_size, self.base_half_height, self.rim_height, self.mass) <= 0:
            raise ValueError(f"receptacle {self.uid!r}: sizes and mass must be positive")

    @property
    def round(self) -> bool:
        return self.shape in ("bowl", "plate")

    @property
    def half_extents(self) -> tuple[float, float, float]:
        """Half extents of the bounding box; the body origin is at its centre."""
        return (self.half_size[0], self.half_size[1], self.base_half_height + self.rim_height / 2)

    @property
    def inner_half_size(self) -> tuple[float, float]:
        """Half extents (x, y) of the free floor inside the rim."""
        return (self.half_size[0] - 2 * self.WALL, self.half_size[1] - 2 * self.WALL)

    @property
    def color(self) -> str:
        return self.description.split()[0]

    def geoms(self) -> list[ReceptacleGeom]:
        """``(suffix, type, size, pos, yaw)`` of every geom, in the body frame."""
        hz = self.half_extents[2]
        base_z = -hz + self.base_half_height
        wall_hz = self.rim_height / 2
        wall_z = -hz + 2 * self.base_half_height + wall_hz
        w = self.WALL
        if self.round:
            r = self.half_size[0]
            out: list[ReceptacleGeom] = [("_base", "cylinder", (r, self.base_half_height), (0.0, 0.0, base_z), 0.0)]
            half_len = (r - w) * np.tan(np.pi / self.RIM_SEGMENTS) + w
            for k in range(self.RIM_SEGMENTS):
                a = 2 * np.pi * k / self.RIM_SEGMENTS
                pos = ((r - w) * np.cos(a), (r - w) * np.sin(a), wall_z)
                out.append((f"_rim{k}", "box", (w, half_len, wall_hz), pos, float(a)))
            return out
        hx, hy = self.half_size
        out = [("_base", "box", (hx, hy, self.base_half_height), (0.0, 0.0, base_z), 0.0)]
        out += [(f"_wall{k}", "box", (w, hy, wall_hz), (s * (hx - w), 0.0, wall_z), 0.0)
                for k, s in enumerate((1.0, -1.0))]
        out += [(f"_wall{k + 2}", "box", (hx - 2 * w, w, wall_hz), (0.0, s * (hy - w), wall_z), 0.0)
                for k, s in enumerate((1.0, -1.0))]
        return out

    def metadata(self) -> dict:
        """The asset-library metadata document (MolmoSpaces' fields, plus ``receptacle``)."""
        return {**_metadata_doc(self, "receptacle"), "receptacle": True}

    def mjcf(self) -> str:
        """A standalone MJCF document: one free body ``uid`` holding base and rim geoms."""
        n = len(self.geoms())
        rgba = " ".join(f"{v:g}" for v in self.rgba)
        lines = []
        for suffix, kind, size, pos, yaw in self.geoms():
            quat = f"{np.cos(yaw / 2):.9g} 0 0 {np.sin(yaw / 2):.9g}"
            lines.append(
                f'      <geom name="{self.uid}{suffix}" type="{kind}" size="{" ".join(f"{v:.9g}" for v in size)}" '
                f'pos="{" ".join(f"{v:.9g}" for v in pos)}" quat="{quat}" rgba="{rgba}" mass="{self.mass / n:.9g}" '
                'friction="1.0 0.01 0.001" condim="4" contype="1" conaffinity="1"/>')
        return (f'<mujoco model="{self.uid}">\n  <worldbody>\n    <body name="{self.uid}">\n'
                f'      <freejoint name="{self.uid}_free"/>\n' + "\n".join(lines) + "\n"
                "    </body>\n  </worldbody>\n</mujoco>\n")


_RECEPTACLE_KINDS = {  # category -> (shape, half_size, base half height, rim height, mass, material, synset)
    "bowl": ("bowl", (0.075, 0.075), 0.004, 0.035, 0.25, "ceramic", "bowl.n.03"),
    "plate": ("plate", (0.09, 0.09), 0.004, 0.014, 0.3, "ceramic", "plate.n.04"),
    "tray": ("tray", (0.095, 0.08), 0.004, 0.02, 0.3, "plastic", "tray.n.01"),
    "box": ("box", (0.075, 0.075), 0.004, 0.045, 0.25, "cardboard", "box.n.01"),
}
_RECEPTACLE_COLORS = {"red": RED, "green": GREEN, "blue": BLUE, "yellow": YELLOW, "white": WHITE}

def _metadata_doc(obj: BuiltinObject | BuiltinReceptacle, kind: str) -> dict:
    """MolmoSpaces' asset metadata fields for a built-in primitive asset."""
    hx, hy, hz = obj.half_extents
    words = obj.description.split()
    return {
        "assetId": obj.uid,
        "category": obj.category,
        "description": obj.description,
        "description_long": f"a {obj.description} ({kind}, {obj.mass * 1000:.0f} g)",
        "description_short": {
            "one_word": words[-1],
            "two_words": " ".join(words[-2:]),
            "three_words": " ".join(words[-3:]),
        },
        "synset": obj.synset,
        "mass": obj.mass,
        "boundingBox": {"x": round(2 * hx, 6), "y": round(2 * hy, 6), "z": round(2 * hz, 6)},
    }


BUILTIN_RECEPTACLES: dict[str, BuiltinReceptacle] = {
    f"builtin_{color}_{category}": BuiltinReceptacle(f"builtin_{color}_{category}", category, shape, size, base, rim,
                                                     rgba, mass, f"{color} {material} {category}", synset)
    for category, (shape, size, base, rim, mass, material, synset) in _RECEPTACLE_KINDS.items()
    for color, rgba in _RECEPTACLE_COLORS.items()
}

#: colours the color task paints receptacles with (name -> rgba)
PAINT_COLORS: dict[str, tuple[float, float, float, float]] = {
    "red": RED, "green": GREEN, "blue": BLUE, "yellow": YELLOW, "orange": ORANGE, "purple": PURPLE, "white": WHITE,
}
