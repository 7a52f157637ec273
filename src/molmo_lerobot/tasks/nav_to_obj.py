"""Navigation to an object (a task plugin: task type ``nav_to_obj``), MolmoSpaces' ``NavToObjTask``
(``molmo_spaces/tasks/nav_task.py``), on episodes in their ``NavToObjTaskSpec`` shape, unchanged.

The targets are ``task.pickup_obj_candidates`` (every instance of the target type) or, without
candidates, ``task.pickup_obj_name`` alone. Where the scene metadata gives categories, the candidates
are first narrowed to the category of ``task.pickup_obj_category`` (else of ``pickup_obj_name``)
as their ``_reconstruct_candidate_list_if_needed`` does; candidates missing from the scene are skipped
(an episode with none left is an error naming the field).

Each step the *nearest* target is the one with the least planar (x, y) distance from the robot base
(the ``base`` move group's x, y for a mobile robot, else ``task.robot_base_pose``). Its reward is 0
unless it is visible from the robot's ``head_camera`` — any pixel of a segmentation render at the
episode's resolution showing a visible geom (groups 0–2) of its subtree, their ``check_visibility`` —
and otherwise ``max(0, 1 - distance / succ_pos_threshold)``; success is a reward above 0 (so the
distance must be *below* the threshold, default 1.5 m).

The prompt is theirs (``get_task_description``): :func:`nav_prompt`. The default horizon is their
``NavToObjBaseConfig``'s 500 steps of 200 ms.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.benchmark.molmospaces import task_aliases
from molmo_lerobot.benchmark.task_specs import NavToObjTaskSpec
from molmo_lerobot.tasks.base import SpecProblem, Task, TaskType

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env

#: the camera the target must be seen from (their camera registry name)
HEAD_CAMERA = "head_camera"


def nav_prompt(object_name: str, n_candidates: int = 1) -> str:
    """MolmoSpaces' instruction: ``Navigate to the X``, or ``Navigate to any X (n available)``."""
    return f"Navigate to any {object_name} ({n_candidates} available)" if n_candidates > 1 \
        else f"Navigate to the {object_name}"


def candidate_names(task: NavToObjTaskSpec, objects: dict[str, Any]) -> list[str]:
    """The episode's target instances, narrowed by category where ``objects`` (scene metadata) knows it."""
    name = task.pickup_obj_name
    candidates = list(task.pickup_obj_candidates or [])
    if not candidates:
        return [name]
    category = (task.model_extra or {}).get("pickup_obj_category") or objects.get(name, {}).get("category")
    if category is None:
        return candidates
    same = [c for c in candidates if objects.get(c, {}).get("category") == category]
    return same or candidates


class NavToObjTask(Task[NavToObjTaskSpec]):
    """Reach within ``succ_pos_threshold`` of the nearest target, seeing it (module docstring)."""

    def __init__(self, spec: NavToObjTaskSpec, env: Env) -> None:
        self.spec, self.env = spec, env
        self.threshold = float(spec.succ_pos_threshold)
        if HEAD_CAMERA not in env.camera_names:
            raise ValueError(f"cameras: nav_to_obj judges visibility from {HEAD_CAMERA!r}, which the episode's "
                             f"cameras ({', '.join(env.camera_names) or 'none'}) do not include")
        names = candidate_names(spec, env.scene_metadata.get("objects", {}))
        field = "task.pickup_obj_candidates" if spec.pickup_obj_candidates else "task.pickup_obj_name"
        present = [n for n in names if n in self._bodies()]
        if not present:
            raise ValueError(f"{field}: none of {names} is a body in the scene")
        self.targets = present
        self._ids = np.array([env.body_id(n, field) for n in present])
        self._cache: tuple[bytes, float, bool] | None = None

    def _bodies(self) -> set[str]:
        m = self.env.model
        return {m.body(b).name for b in range(m.nbody)}

    def setup(self) -> None:
        """Nothing to remember: the rule depends on the current state only."""
        self._cache = None

    def base_xy(self) -> np.ndarray:
        """The robot base's planar position now."""
        if "base" in self.env.move_groups:
            return self.env.robot.qpos(self.env.data, "base")[:2]
        return self.env.base_pose[:2].copy()

    def nearest(self) -> tuple[str, float]:
        """The nearest target (their priority order: planar distance from the base) and its distance."""
        d = np.linalg.norm(self.env.data.xpos[self._ids][:, :2] - self.base_xy(), axis=1)
        k = int(np.argmin(d))
        return self.targets[k], float(d[k])

    def visible(self, name: str) -> bool:
        """Whether any pixel of the head camera shows ``name``."""
        return self.env.visible_fractions(HEAD_CAMERA, [name])[name] > 0.0

    def _judge(self) -> tuple[float, bool]:
        """(distance, visible) of the nearest target in the current state, rendering only when the
        distance could pass (a farther target scores 0 whatever it shows) and the state (``qpos`` at
        0.1 mm / 1e-4 rad) changed since the last render."""
        d = self.env.data
        key = (np.round(d.qpos, 4) + 0.0).tobytes()  # unchanged at 0.1 mm / 1e-4 rad looks the same (+0.0: no -0.0)
        if self._cache is None or self._cache[0] != key:
            name, dist = self.nearest()
            self._cache = (key, dist, dist < self.threshold and self.visible(name))
        return self._cache[1], self._cache[2]

    def reward(self) -> float:
        """Theirs: 0 unless visible, else ``max(0, 1 - distance / succ_pos_threshold)``."""
        dist, seen = self._judge()
        if not seen:  # seen implies distance < threshold
            return 0.0
        return max(0.0, 1.0 - dist / self.threshold)

    def success(self) -> bool:
        return self.reward() > 0.0


class NavToObjTaskType(TaskType[NavToObjTaskSpec]):
    name = "nav_to_obj"
    aliases = ("molmo_lerobot.tasks.nav_to_obj.NavToObjTask", *task_aliases("nav_to_obj"))
    spec_model = NavToObjTaskSpec
    default_horizon_sec = 100.0  # their NavToObjBaseConfig: task_horizon 500 steps × policy_dt 200 ms

    def thresholds(self, spec: EpisodeSpec) -> dict[str, Any]:
        return {"succ_pos_threshold": float(self.task_spec(spec).succ_pos_threshold)}

    def spec_problems(self, spec: EpisodeSpec, scene_metadata: Callable[[], Mapping[str, Any] | None]
                      ) -> list[SpecProblem]:
        """A target the house's metadata does not list (where it lists its objects) can never be reached."""
        objects = (scene_metadata() or {}).get("objects")
        if not isinstance(objects, Mapping):
            return []
        task = self.task_spec(spec)
        names = candidate_names(task, dict(objects))
        if any(n in objects for n in names):
            return []
        field = "task.pickup_obj_candidates" if task.pickup_obj_candidates else "task.pickup_obj_name"
        return [SpecProblem(field, f"none of {names} is an object of house {spec.house_index} "
                                   f"({len(objects)} objects, e.g. {', '.join(sorted(objects)[:3])})")]

    def create(self, spec: EpisodeSpec, env: Env) -> NavToObjTask:
        return NavToObjTask(self.task_spec(spec), env)


@hookimpl
def molmo_task_types() -> list[TaskType[Any]]:
    return [NavToObjTaskType()]
