"""MolmoSpaces' success checks on given MuJoCo states (a helper for tests/parity/theirs.py; runs in the
parity venv, never in ours).

Their task classes are built with their own constructors and judged with their own ``judge_success``
(what their evaluation records each step). Substituted, and only because it needs their gated assets:

* the environment: their ``BaseMujocoEnv`` loads their robot models and scene archives, so a stand-in
  (:class:`SceneEnv`) exposes what the success checks read — the model and data, the scene metadata,
  one :class:`ObjectManager` (theirs), the robot's root body and the robot namespace;
* the experiment config: a namespace with the five fields their task constructors read (their
  ``MlSpacesExpConfig`` needs a robot config and policy classes); the task config is theirs;
* downloaded resources touched while importing or judging: ``theirs.offline`` (our objects carry no
  ``asset_id``, so the empty annotation database is only asked for ``"DUMMY"``, which it never holds;
  the material tables are read when the colour task's sampler module is imported).
"""

from __future__ import annotations

from types import SimpleNamespace

import mujoco
import numpy as np
from theirs import contact_table, offline

offline()

from molmo_spaces.configs import task_configs  # noqa: E402
from molmo_spaces.env.object_manager import ObjectManager  # noqa: E402
from molmo_spaces.tasks.opening_tasks import OpeningTask  # noqa: E402
from molmo_spaces.tasks.pick_and_place_color_task import PickAndPlaceColorTask  # noqa: E402
from molmo_spaces.tasks.pick_and_place_next_to_task import PickAndPlaceNextToTask  # noqa: E402
from molmo_spaces.tasks.pick_and_place_task import PickAndPlaceTask  # noqa: E402
from molmo_spaces.tasks.pick_task import PickTask  # noqa: E402

TASKS = {
    "pick": (PickTask, task_configs.PickTaskConfig),
    "pick_and_place": (PickAndPlaceTask, task_configs.PickAndPlaceTaskConfig),
    "pick_and_place_next_to": (PickAndPlaceNextToTask, task_configs.PickAndPlaceNextToTaskConfig),
    "pick_and_place_color": (PickAndPlaceColorTask, task_configs.PickAndPlaceColorTaskConfig),
    "open": (OpeningTask, task_configs.OpeningTaskConfig),
    "close": (OpeningTask, task_configs.OpeningTaskConfig),
}


class SceneEnv:
    """Stand-in for their ``BaseMujocoEnv`` over one model and data (batch of one)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, robot_root: int, robot_namespace: str,
                 metadata: dict) -> None:
        self.n_batch, self.current_batch_index = 1, 0
        self.mj_model = self._mj_model = self.current_model = model
        self.mj_datas = [data]
        self.current_scene_metadata = metadata
        self.config = SimpleNamespace(robot_config=SimpleNamespace(robot_namespace=robot_namespace))
        self.current_robot = SimpleNamespace(robot_view=SimpleNamespace(base=SimpleNamespace(root_body_id=robot_root)))
        self.robots = [self.current_robot]
        self.object_managers = [ObjectManager(self, 0)]


def judge(inputs: dict) -> dict:
    """Judge every state of every episode with a fresh task per episode.

    inputs: ``xml`` (the scene), ``metadata`` (scene metadata), ``robot_root`` (body name),
    ``robot_namespace``, ``episodes``: ``[{"task": {task_type, config fields...}, "first": i, "count": n}]``
    over the rows of ``qpos`` (S, nq) and ``xfrc`` (S, nbody, 6), in order.
    Returns ``success`` (S,) and ``contacts`` (per state, ``theirs.contact_table`` as lists).
    """
    model = mujoco.MjModel.from_xml_string(inputs["xml"])
    qpos, xfrc = inputs["qpos"], inputs["xfrc"]
    success = np.zeros(len(qpos), dtype=bool)
    contacts: list = [None] * len(qpos)
    for episode in inputs["episodes"]:
        data = mujoco.MjData(model)
        env = SceneEnv(model, data, model.body(inputs["robot_root"]).id, inputs["robot_namespace"],
                       inputs["metadata"])
        fields = dict(episode["task"])
        task_type = fields.pop("task_type")
        task_cls, config_cls = TASKS[task_type]
        config = SimpleNamespace(task_type=task_type, task_config=config_cls(use_sensors=False, **fields),
                                 ctrl_dt_ms=2, policy_dt_ms=66, task_horizon=None)
        task = task_cls(env, config)
        for s in range(episode["first"], episode["first"] + episode["count"]):
            data.qpos[:], data.qvel[:] = qpos[s], 0.0
            data.xfrc_applied[:] = xfrc[s]
            mujoco.mj_forward(model, data)
            success[s] = bool(task.judge_success())
            contacts[s] = contact_table(model, data).tolist()
    return {"success": success, "contacts": contacts}


def paint(inputs: dict) -> dict:
    """Their JSON evaluation's colouring of ``object_colors`` (``JsonEvalTaskSampler._randomize_colors``)
    on a fresh model per colouring; returns every geom's ``rgba`` (C, ngeom, 4) and ``matid`` (C, ngeom)."""
    import molmo_spaces.evaluation  # noqa: F401  (their import order: evaluation before the sampler)
    from molmo_spaces.tasks.json_eval_task_sampler import JsonEvalTaskSampler

    rgba, matid = [], []
    for colors in inputs["colorings"]:
        model = mujoco.MjModel.from_xml_string(inputs["xml"])
        env = SceneEnv(model, mujoco.MjData(model), model.body(inputs["robot_root"]).id, inputs["robot_namespace"],
                       inputs["metadata"])
        sampler = SimpleNamespace(episode_spec=SimpleNamespace(task={"object_colors": colors}))
        JsonEvalTaskSampler._randomize_colors(sampler, env)
        rgba.append(model.geom_rgba.copy())
        matid.append(model.geom_matid.copy())
    return {"rgba": np.array(rgba), "matid": np.array(matid)}
