"""MetaWorld as an env suite: ``metaworld`` 3.0's Sawyer tasks in LeRobot's ``metaworld`` convention.

``lerobot-eval --env.type=metaworld --env.task=<group or task>`` builds, per task, LeRobot's ``MetaworldEnv``: the
task's ``MT1`` benchmark seeded 42, its first train task, the ``corner2`` camera moved to (0.75, 0.075, 0.7) and its
renders flipped on both axes, object positions drawn from the env's seeded generator (``env.seed(s)`` then
``reset``). The policy sees ``observation.image`` (that 480² render) and ``observation.state`` (the first 4 entries of
MetaWorld's 39-D observation: hand position and gripper opening, as float32), and returns a 4-D action (hand
position delta and gripper effort in [-1, 1], which MetaWorld clips). A step succeeds when MetaWorld's
``info["success"]`` says so, and that step ends the episode (``terminated``). Episodes last at most MetaWorld's
``max_path_length``, 500 steps: ``lerobot-eval`` stops at ``MetaworldEnv._max_episode_steps`` (500); the config's
``episode_length`` (400) is not passed to the env and is unused. The rate is 80 steps/s (LeRobot's ``fps``:
MetaWorld's 5 physics steps of 2.5 ms). Episode ``k`` of each task of a run with seed ``S`` is seeded ``S + k``
(``eval_policy_all`` with ``--eval.batch_size=1``), tasks in LeRobot's order (its ``metaworld_config.json``).

Benchmarks (``benchmark=<name>``, each a ``conf/benchmark/<name>.yaml``): ``metaworld_<group>`` for LeRobot's
task groups (``--env.task=easy`` … ``very_hard``), ``metaworld_mt50`` for all four in order
(``--env.task=easy,medium,hard,very_hard``), and ``metaworld_<task>`` for one task (``--env.task=reach-v3``).
The env runs in the worker's own process (metaworld shares the main venv), as PushT does.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from molmo_lerobot.policies.scripted_metaworld import lerobot_metaworld_config
from molmo_lerobot.suites.episode import SuiteEpisode

#: MetaWorld's ``max_path_length`` (a step past it raises), and ``lerobot-eval``'s step limit
MAX_STEPS = 500
#: LeRobot's ``metaworld`` ``fps`` (MetaWorld's 5 × 2.5 ms per step)
CONTROL_HZ = 80
#: LeRobot's ``MetaworldEnv`` render size (MetaWorld's default; LeRobot's observation size options do not change it)
IMAGE_SIZE = 480
ACTION_DIM = 4
STATE_DIM = 4
#: MetaWorld clips each action entry to this box
ACTION_BOUNDS = (-1.0, 1.0)
#: the one move group a molmo-eval policy sees: the 4-D action (hand position delta, gripper effort) is its
#: command, ``observation.state`` (hand position, gripper opening) its observed ``qpos``
MOVE_GROUP = "hand"
CAMERA = "image"
#: LeRobot's camera and its position, and the seed of its ``MT1`` benchmarks
CAMERA_NAME, CAMERA_POS, MT1_SEED = "corner2", (0.75, 0.075, 0.7), 42
#: LeRobot's task groups, in the order ``metaworld_mt50`` plays them
GROUPS = ("easy", "medium", "hard", "very_hard")
ALL = "mt50"
PREFIX = "metaworld_"
DISTRIBUTIONS = ("metaworld",)


def task_names() -> list[str]:
    """Every task, in LeRobot's group order."""
    groups = lerobot_metaworld_config().get("DIFFICULTY_TO_TASKS", {})
    return [task for group in GROUPS for task in groups.get(group, [])]


def benchmarks() -> dict[str, int]:
    """Every MetaWorld benchmark and its step limit: the groups, ``metaworld_mt50``, one per task."""
    return {f"{PREFIX}{name}": MAX_STEPS for name in (*GROUPS, ALL, *task_names())}


def catalogue(benchmark: str) -> list[dict[str, Any]]:
    """The tasks of ``benchmark`` in ``lerobot-eval``'s order, each with its group, id within the group (LeRobot's
    ``task_id``), name and instruction (LeRobot's task description)."""
    table = lerobot_metaworld_config()
    name = benchmark.removeprefix(PREFIX)
    if name not in (*GROUPS, ALL, *task_names()) or not benchmark.startswith(PREFIX):
        raise ValueError(f"unknown MetaWorld benchmark {benchmark!r}")
    groups = GROUPS if name == ALL else (name,)
    out = []
    for group in groups:
        tasks = table["DIFFICULTY_TO_TASKS"].get(group, [group])  # not a group: one task, LeRobot's "custom task"
        out += [{"group": group, "task_id": i, "task": task, "instruction": table["TASK_DESCRIPTIONS"][task]}
                for i, task in enumerate(tasks)]
    return out


@dataclass(frozen=True)
class MetaWorldEpisode(SuiteEpisode):
    suite: str
    #: LeRobot's task group (``easy`` …; a task's own name for a one-task benchmark) and the task's id in it
    group: str
    task_id: int
    task: str
    seed: int
    horizon: int
    instruction: str


def plan_episodes(suite: str, tasks: Iterable[Mapping[str, Any]], episodes_per_task: int, seed: int = 0,
                  horizon: int | None = None) -> list[MetaWorldEpisode]:
    """``episodes_per_task`` episodes of each task in order, episode ``k`` seeded ``seed + k``; ``horizon``
    overrides the 500-step limit."""
    steps = MAX_STEPS if horizon is None else int(horizon)
    return [MetaWorldEpisode(suite, str(t["group"]), int(t["task_id"]), str(t["task"]), seed + k, steps,
                             str(t["instruction"]))
            for t in tasks for k in range(episodes_per_task)]


def episode_problems(episode: MetaWorldEpisode, tasks: Iterable[Mapping[str, Any]]) -> list[str]:
    """What is wrong with ``episode`` against the benchmark's catalogue: a task of it, with its group, id and
    instruction; a horizon MetaWorld can play (at most its ``max_path_length``)."""
    by_name = {str(t["task"]): t for t in tasks}
    task = by_name.get(episode.task)
    if task is None:
        return [f"task {episode.task!r}: not a task of {episode.suite}"]
    out = [f"{key} {getattr(episode, key)!r}: task {episode.task}'s is {task[key]!r}"
           for key in ("group", "task_id", "instruction") if getattr(episode, key) != task[key]]
    if isinstance(episode.horizon, int) and episode.horizon > MAX_STEPS:
        out.append(f"horizon {episode.horizon}: MetaWorld plays at most {MAX_STEPS} steps")
    return out


def task_label(episode: MetaWorldEpisode) -> str:
    """The episode's ``per_task`` key and task type: ``metaworld/reach-v3`` (whatever the benchmark)."""
    return f"metaworld/{episode.task}"


def policy_observation(obs: Mapping[str, Any], step: int) -> dict[str, Any]:
    """A MetaWorld observation in our policy interface: camera ``image`` (when drawn), the 4-D state as
    ``qpos["hand"]``."""
    out: dict[str, Any] = {"qpos": {MOVE_GROUP: obs["observation.state"]}, "prompt": obs["task"], "step": step}
    if "observation.image" in obs:
        out["images"] = {CAMERA: obs["observation.image"]}
    return out


class MetaWorldSuite:
    """MetaWorld's env of the current task in this process, built as LeRobot's ``MetaworldEnv`` builds it, behind
    the suite interface :class:`~molmo_lerobot.suites.benchmark.SuiteSession` plays (``tasks``, ``reset``,
    ``step``, ``close``, ``alive``). :attr:`raw_observation` is MetaWorld's 39-D observation of the state now
    (what its scripted experts read)."""

    #: in the worker's own process: never lost on its own
    alive = True

    def __init__(self, image_size: int = IMAGE_SIZE) -> None:
        self.image_size = image_size
        self.task: str | None = None
        self.env: Any = None
        self.raw_observation = np.zeros(39)

    def tasks(self, suite: str) -> list[dict[str, Any]]:
        return catalogue(suite)

    def _open(self, task: str) -> None:
        """MetaWorld's env of ``task`` as LeRobot's ``MetaworldEnv._ensure_env`` makes it."""
        import metaworld

        self.close()
        mt1 = metaworld.MT1(task, seed=MT1_SEED)
        env = mt1.train_classes[task](render_mode="rgb_array", camera_name=CAMERA_NAME, width=self.image_size,
                                      height=self.image_size)
        env.set_task(mt1.train_tasks[0])
        env.model.cam_pos[2] = CAMERA_POS
        env.reset()
        env._freeze_rand_vec = False  # object positions drawn at each reset …
        env.seeded_rand_vec = True  # … from the env's seeded generator
        self.env, self.task = env, task

    def reset(self, episode: MetaWorldEpisode) -> dict[str, Any]:
        if episode.task != self.task:
            self._open(episode.task)
        self.env.seed(episode.seed)
        raw, _info = self.env.reset(seed=episode.seed)
        return self._observation(raw, images=True)

    def step(self, action: np.ndarray, images: bool = True) -> dict[str, Any]:
        """One step with a 4-D action, as float32 (what a LeRobot policy's tensor gives the env); ``images``:
        draw the frame (a 480² render, the step's main cost)."""
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (ACTION_DIM,):
            raise ValueError(f"MetaWorld: an action is 4-D (hand delta, gripper), got shape {action.shape}")
        raw, reward, done, _truncated, info = self.env.step(action)
        success = bool(info.get("success", 0))
        return {"observation": self._observation(raw, images), "reward": float(reward),
                "terminated": bool(done) or success, "success": success}

    def _observation(self, raw: np.ndarray, images: bool) -> dict[str, Any]:
        self.raw_observation = raw
        out: dict[str, Any] = {"observation.state": np.asarray(raw[:STATE_DIM], dtype=np.float32)}
        if images:  # the corner2 camera draws upside down and mirrored: LeRobot flips both axes
            out["observation.image"] = np.ascontiguousarray(np.flip(self.env.render(), (0, 1)))
        return out

    def close(self) -> None:
        env, self.env, self.task = self.env, None, None
        if env is not None:
            env.close()
