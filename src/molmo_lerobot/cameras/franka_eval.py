"""MolmoSpaces' eval camera system, ``FrankaEvalCameraSystem`` (their ``--use_eval_cameras
--camera_rand_level L``), for ``franka_droid``: it replaces the episode's recorded cameras.

Images are 640 × 368, as theirs (the ``camera.eval`` episode override sets ``img_resolution``).
``wrist_camera``: the robot's ``gripper/wrist_camera`` mount, fov 52°, with mount noise.
``exo_camera_1``: a world camera whose level-0 pose is DROID's shoulder camera (``fr3_link0`` +
``[0.1, 0.57, 0.66]``, fov 71°) in the reset scene. Around the workspace centre (the centroid of
the task objects' recorded poses, ``scene_modifications.object_poses``, and the TCP) its azimuth,
horizontal distance and height are shifted by uniform draws (distance at least 0.1 m); its
orientation is the calibrated one slerped towards looking at the centre (plus look-at jitter);
its fov is drawn. A draw is repeated until every task object and the gripper cover 1e-4 of the
image (a segmentation render), at most 50 times; otherwise the episode fails to build.

The level ``L`` in 0–100 sets every range by piecewise-linear interpolation between anchors at
levels 0, 10, 40, 75 and 100 (:data:`WRIST_ANCHORS`, :data:`EXO_ANCHORS`: MolmoSpaces' table):
level 0 is the calibrated rig with no noise; level 100 moves the exterior camera up to ±180°
around the scene, 0.5 m nearer to 1.5 m further, 0.3 m lower to 0.8 m higher, fov 64–78°.

Draws come from ``numpy.random.RandomState(seed)`` with MolmoSpaces' per-episode seed
(:func:`episode_camera_seed`) in their order (wrist fov, position, orientation; then per exo
draw azimuth, distance, height, look-at jitter, fov), so an episode gets their cameras, the same
on every worker and at every run.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from molmo_lerobot.cameras.base import CameraSystem
from molmo_lerobot.cameras.franka_mounts import (
    ARM_ROOT,
    EXO_CAMERA_1,
    MountNoise,
    add_wrist,
    arm_root,
    gripper_body,
    noisy_mount,
    place_until_seen,
    task_objects,
    wrist_mount,
)
from molmo_lerobot.hashing import episode_digest
from molmo_lerobot.poses import Vector, look_rotation, mat_to_quat

#: (width, height) their eval cameras render at, whatever the episode's ``img_resolution``
EVAL_IMG_RESOLUTION = (640, 368)
WRIST_FOV = 52.0
EXO_FOV = 71.0
EXO_ATTEMPTS = 50
MIN_EXO_DISTANCE = 0.10
#: the levels at which MolmoSpaces gives each range
ANCHOR_LEVELS = (0.0, 10.0, 40.0, 75.0, 100.0)
_WRIST_POS = ((-0.015, -0.005, -0.01), (0.015, 0.005, 0.01))
#: wrist noise at each anchor level: fov (deg), position (m), orientation (± deg about x, y, z)
WRIST_ANCHORS = (
    MountNoise((0.0, 0.0), ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), (0.0, 0.0, 0.0)),
    *[MountNoise((-4.0, 4.0), _WRIST_POS, (8.0, 4.0, 4.0))] * 4,
)


@dataclass(frozen=True)
class ExoRanges:
    """The exterior camera's shifts (radians, metres), look-at weight (0: calibrated orientation,
    1: look at the workspace centre), look-at jitter (m per axis) and fov range (deg)."""

    azimuth: tuple[float, float]
    distance: tuple[float, float]
    height: tuple[float, float]
    lookat_weight: float
    lookat_noise: tuple[float, float]
    fov: tuple[float, float]


EXO_ANCHORS = (
    ExoRanges((0.0, 0.0), (0.0, 0.0), (0.0, 0.0), 0.0, (0.0, 0.0), (71.0, 71.0)),
    ExoRanges((-math.pi / 4, math.pi / 4), (-0.05, 0.05), (-0.05, 0.05), 1.0, (-0.01, 0.01), (71.0, 71.0)),
    ExoRanges((-math.pi / 2, math.pi / 2), (-0.5, 0.5), (-0.1, 0.5), 1.0, (-0.05, 0.05), (64.0, 72.0)),
    ExoRanges((-math.pi, math.pi), (-0.5, 1.0), (-0.2, 0.7), 1.0, (-0.1, 0.1), (64.0, 72.0)),
    ExoRanges((-math.pi, math.pi), (-0.5, 1.5), (-0.3, 0.8), 1.0, (-0.15, 0.15), (64.0, 78.0)),
)


def _interpolate(level: float, values: Sequence[float]) -> float:
    """``values`` (one per anchor level) at ``level``, piecewise linear, constant beyond the ends."""
    if level <= ANCHOR_LEVELS[0]:
        return values[0]
    for (lo, hi), (v_lo, v_hi) in zip(pairwise(ANCHOR_LEVELS), pairwise(values), strict=True):
        if level <= hi:
            return v_lo + (v_hi - v_lo) * ((level - lo) / (hi - lo))
    return values[-1]


def _at_level(level: float, anchors: Sequence[Any]) -> Any:
    """The anchors' dataclass with every (nested) number interpolated at ``level``."""
    def blend(*values: Any) -> Any:
        if isinstance(values[0], tuple):
            return tuple(blend(*parts) for parts in zip(*values, strict=True))
        return _interpolate(level, values)

    cls = type(anchors[0])
    return cls(*(blend(*(getattr(a, f) for a in anchors)) for f in cls.__dataclass_fields__))


def wrist_noise(level: float) -> MountNoise:
    return _at_level(level, WRIST_ANCHORS)


def exo_ranges(level: float) -> ExoRanges:
    return _at_level(level, EXO_ANCHORS)


def episode_camera_seed(episode: Any) -> int:
    """MolmoSpaces' eval camera seed of an episode: the first 32 bits of the SHA-256 of its
    identity — scene dataset, split, house, source file and trajectory key, seed — joined by
    ``|``. It does not depend on the level: a level sweep keeps each episode's seed."""
    parts = [str(episode.scene_dataset), str(episode.data_split), str(episode.house_index)]
    if episode.source is not None:
        parts += [str(episode.source.h5_file), str(episode.source.traj_key)]
    if episode.seed is not None:
        parts.append(str(episode.seed))
    return int.from_bytes(hashlib.sha256("|".join(parts).encode()).digest()[:4], "big")


def workspace_centre(episode: Any, tcp: Sequence[float]) -> np.ndarray:
    """Centroid of the task objects' recorded positions (those ``object_poses`` holds) and ``tcp``."""
    poses = episode.scene_modifications.object_poses
    points = [poses[name][:3] for name in task_objects(episode) if name in poses]
    return np.mean([*points, tcp], axis=0)


def eval_exo_draws(ref_pos: np.ndarray, ref_rot: np.ndarray, centre: np.ndarray, ranges: ExoRanges,
                   rng: Any) -> Callable[[], tuple[np.ndarray, list[float], float]]:
    """Draws of the exterior camera (world position, wxyz quaternion, fovy) around ``centre``
    from its calibrated pose (``ref_pos``, rotation matrix ``ref_rot``), in MolmoSpaces' order."""
    delta = ref_pos - centre
    azimuth0, distance0, height0 = math.atan2(delta[1], delta[0]), math.hypot(delta[0], delta[1]), delta[2]
    calibrated = Rotation.from_matrix(ref_rot)

    def draw() -> tuple[np.ndarray, list[float], float]:
        azimuth = azimuth0 + rng.uniform(*ranges.azimuth)
        distance = max(distance0 + rng.uniform(*ranges.distance), MIN_EXO_DISTANCE)
        height = height0 + rng.uniform(*ranges.height)
        pos = centre + np.array([distance * math.cos(azimuth), distance * math.sin(azimuth), height])
        lookat = centre + rng.uniform(*ranges.lookat_noise, size=3)
        looking = Rotation.from_matrix(look_rotation(lookat - pos, (0.0, 0.0, 1.0)))
        rot = Slerp([0.0, 1.0], Rotation.concatenate([calibrated, looking]))(ranges.lookat_weight)
        fovy = EXO_FOV + (rng.uniform(*ranges.fov) - EXO_FOV)  # their arithmetic (shift from the base fov), bit for bit
        return pos, mat_to_quat(rot.as_matrix()), float(fovy)

    return draw


def _model_body(model: mujoco.MjModel, name: str) -> int:
    """Id of the compiled model's body ``name`` (robot bodies carry a prefix)."""
    found = [i for i in range(model.nbody) if model.body(i).name == name or model.body(i).name.endswith("/" + name)]
    if len(found) != 1:
        raise ValueError(f"camera system: no (unique) body {name!r} in the scene")
    return found[0]


class FrankaEvalCameraSystem(CameraSystem):
    """MolmoSpaces' eval cameras at randomization ``level`` 0–100 (module docstring)."""

    name = "FrankaEvalCameraSystem"
    aliases = ("eval",)
    places_in_scene = True
    replaces_recorded = True

    def __init__(self, level: float = 0.0) -> None:
        if not 0.0 <= level <= 100.0:
            raise ValueError(f"{self.name}: level must be in 0-100, got {level!r}")
        self.level = float(level)

    def configured(self, options: Mapping[str, Any]) -> FrankaEvalCameraSystem:
        return FrankaEvalCameraSystem(float(options.get("rand_level") or 0.0))

    def episode_key(self, episode: Any) -> str:
        return f"{episode_digest(episode).hex()}@{self.level:g}"

    def add_cameras(self, world: mujoco.MjSpec, cameras: Sequence[Any],
                    find_body: Callable[[str], mujoco.MjsBody | None], episode: Any = None) -> list[str]:
        mount = wrist_mount(world)
        add_wrist(world, mount.pos, mount.quat, WRIST_FOV)  # its noise is drawn by place(), first
        arm_root(find_body)  # the exterior camera's calibrated pose hangs off it
        world.worldbody.add_camera(name="exo_camera_1", pos=[0.0, 0.0, 0.0])
        return ["wrist_camera", "exo_camera_1"]

    def place(self, env: Any) -> dict[str, tuple[Vector, Vector, float]]:
        m, d, spec = env.model, env.data, env.spec
        rng = np.random.RandomState(episode_camera_seed(spec))
        wrist = m.camera("wrist_camera").id
        poses: dict[str, tuple[Vector, Vector, float]] = {
            "wrist_camera": noisy_mount(m.cam_pos[wrist], m.cam_quat[wrist], WRIST_FOV, wrist_noise(self.level), rng)}
        root = _model_body(m, ARM_ROOT)
        offset, quat, _ = EXO_CAMERA_1
        root_rot = d.xmat[root].reshape(3, 3)
        ref_pos = root_rot @ np.asarray(offset) + d.xpos[root]
        ref_rot = root_rot @ Rotation.from_quat(quat, scalar_first=True).as_matrix()
        centre = workspace_centre(spec, d.site_xpos[env.robot.tcp_site])
        draw = eval_exo_draws(ref_pos, ref_rot, centre, exo_ranges(self.level), rng)
        poses["exo_camera_1"] = place_until_seen(env, "exo_camera_1", [*task_objects(spec), gripper_body(env)],
                                                 EXO_ATTEMPTS, draw, f"{self.name} at level {self.level:g}")
        return poses
