"""Built-in episode overrides (a plugin of the ``molmo_episode_overrides`` hook).

Eval-time options that edit each episode before it runs, deterministically, so that the
edited episode is what the seeds, the rollout and the recorded dataset all see:

* ``custom_object.path``: swap the episode's target object for a user MJCF, keeping its
  position and yaw (resting on the same support), removing the original and renaming the
  task's target to ``custom_object.name``;
* ``camera.overrides``: set fields of named cameras (``{exterior: {fov: 60}}``);
* ``robot.name``: the robot every episode runs with, instead of its ``robot.robot_name`` (MolmoSpaces'
  eval config's ``robot_config``); the episode's ``init_qpos`` must fit its move groups;
* ``robot.base_size``: the robot's pedestal for every episode (``[x, y, z]`` metres, ``null``
  for none; ``default`` leaves each episode's ``robot.base_size`` or the robot's own);
* ``camera.randomization``: level 0-3 of seeded camera jitter (position, direction, field of
  view) of the episode's recorded cameras; the seed comes from the episode's own content, so
  every run, worker and executor sees the same cameras for the same episode. Our own option,
  not MolmoSpaces' camera robustness sweep (that is ``camera.eval=true camera.rand_level=L``);
* ``camera.eval=true`` (or ``camera.system=FrankaEvalCameraSystem``): MolmoSpaces' eval cameras
  render at their own resolution, which becomes the episode's ``img_resolution``.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.schema import EpisodeSpec
from molmo_lerobot.cameras.franka_eval import EVAL_IMG_RESOLUTION
from molmo_lerobot.cameras.options import EVAL_NAMES, run_camera_system
from molmo_lerobot.errors import MolmoError
from molmo_lerobot.hashing import episode_digest

if TYPE_CHECKING:
    from molmo_lerobot.assets.catalog import AssetCatalog
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.run_config import RunConfig

#: per randomization level: position (m), direction (deg), fov (deg), wrist offset (m) jitter
CAMERA_JITTER = {"pos": 0.02, "dir_deg": 2.0, "fov_deg": 2.0, "offset": 0.005}
TARGET_FIELDS = ("pickup_obj_name",)


class OverrideError(MolmoError, ValueError):
    """An eval-time option that cannot be applied to an episode; the message names it."""


@hookimpl
def molmo_episode_overrides(episode: EpisodeSpec, config: RunConfig, context: RunContext) -> EpisodeSpec | None:
    """The run's options (``config``) applied to ``episode``; ``None`` where none changes it."""
    data = episode.model_dump(mode="json")
    changed = False
    if config.custom_object.path:
        _swap_target(data, episode, Path(config.custom_object.path).expanduser(), config.custom_object.name,
                     config.custom_object.description, context.catalog)
        changed = True
    if config.robot.name is not None and config.robot.name != episode.robot.robot_name:
        data["robot"]["robot_name"] = config.robot.name
        changed = True
    if config.robot.base_size != "default":
        data["robot"]["base_size"] = config.robot.base_size
        changed = True
    for name, fields in config.camera.overrides.items():
        cams = [c for c in data["cameras"] if c["name"] == name]
        if not cams:
            raise OverrideError(f"camera.overrides: no camera {name!r} in the episode "
                                f"(cameras: {', '.join(c['name'] for c in data['cameras'])})")
        cams[0].update(fields)
        changed = True
    if (run_camera_system(config.camera.model_dump()) in EVAL_NAMES
            and tuple(data["img_resolution"]) != EVAL_IMG_RESOLUTION):
        data["img_resolution"] = list(EVAL_IMG_RESOLUTION)
        changed = True
    if config.camera.randomization:  # 1-3 (RunConfig checks the level)
        rng = np.random.default_rng(list(episode_digest(episode)[:16]))
        _jitter_cameras(data["cameras"], config.camera.randomization, rng)
        changed = True
    return episode.edited(data) if changed else None


@cache
def _bottom_offset(path: str) -> float:
    """Distance from the MJCF's top body origin down to its lowest geom point."""
    model = mujoco.MjSpec.from_file(path).compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    lowest = np.inf
    for g in range(model.ngeom):
        center, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half + center
        z = (corners @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g])[:, 2]
        lowest = min(lowest, float(z.min()))
    top = model.body_rootid[model.geom_bodyid[0]] if model.ngeom else 1
    return float(data.xpos[top][2] - lowest) if np.isfinite(lowest) else 0.0


def _swap_target(data: dict, episode: EpisodeSpec, path: Path, name: str, description: str | None,
                 catalog: AssetCatalog) -> None:
    task = data["task"]
    field = next((f for f in TARGET_FIELDS if task.get(f)), None)
    if field is None:
        raise OverrideError(f"custom_object: task {episode.task_name!r} has no target object field "
                            f"({', '.join(TARGET_FIELDS)})")
    old = task[field]
    mods = data["scene_modifications"]
    if old not in mods["object_poses"]:
        raise OverrideError(f"custom_object: the episode gives no pose for its target {old!r} "
                            "(scene_modifications.object_poses)")
    pose = list(mods["object_poses"].pop(old))
    try:
        pose[2] -= float(catalog.annotation(old)["boundingBox"]["z"]) / 2  # the original's bottom (upright primitives)
        pose[2] += _bottom_offset(str(path))
    except LookupError:
        pass  # not in an asset library: keep the original height
    mods["removed_objects"] = [*mods.get("removed_objects", []), old]
    mods["added_objects"] = {**mods.get("added_objects", {}), name: str(path.resolve())}
    mods["object_poses"][name] = pose
    task[field] = name
    if "pickup_obj_start_pose" in task:
        task["pickup_obj_start_pose"] = pose
    data["task_relevant_objects"] = [name if o == old else o for o in data.get("task_relevant_objects", [])]
    if description:
        data["language"]["task_description"] = description


def _jitter_cameras(cameras: list[dict], level: int, rng: np.random.Generator) -> None:
    for cam in cameras:
        cam["fov"] = float(np.clip(cam["fov"] + rng.uniform(-1, 1) * CAMERA_JITTER["fov_deg"] * level, 10, 150))
        if cam.get("type") == "exocentric":
            cam["pos"] = (np.asarray(cam["pos"]) + rng.uniform(-1, 1, 3) * CAMERA_JITTER["pos"] * level).tolist()
            forward = np.asarray(cam["forward"], dtype=float)
            forward /= np.linalg.norm(forward)
            axis = np.cross(forward, rng.normal(size=3))
            axis /= np.linalg.norm(axis)
            angle = np.deg2rad(rng.uniform(0, CAMERA_JITTER["dir_deg"] * level))
            cam["forward"] = (forward * np.cos(angle) + np.cross(axis, forward) * np.sin(angle)).tolist()
        elif "camera_offset" in cam:
            cam["camera_offset"] = (np.asarray(cam["camera_offset"])
                                    + rng.uniform(-1, 1, 3) * CAMERA_JITTER["offset"] * level).tolist()
