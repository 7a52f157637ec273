"""A tiny env suite as a molmo_lerobot plugin: a point on [0, 1] moved by velocity commands must come within
:data:`REACH` of a target dot. Its episodes are seeded (the seed places the point and the dot); its frame is an
8 × 8 strip with the point and the dot drawn; it ends on reaching the dot."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from molmo_lerobot import hookimpl
from molmo_lerobot.dataset_layout import OUTCOMES, DatasetLayout, Vector
from molmo_lerobot.suites.benchmark import EnvSuiteKind, ImageSize, SuiteKind, SuiteOptions
from molmo_lerobot.suites.episode import SuiteEpisode

TASKS = ("left", "middle", "right")
TARGETS = {"left": 0.2, "middle": 0.5, "right": 0.8}
REACH = 0.05
MAX_STEPS = 20
SPEED = 0.1


@dataclass(frozen=True)
class DotEpisode(SuiteEpisode):
    suite: str
    task: str
    seed: int
    horizon: int
    instruction: str


class DotOptions(SuiteOptions):
    """``benchmark.*`` of ``dot_reach``: two episodes per task, 8-pixel frames."""

    episodes_per_task: int = 2
    image_size: ImageSize = 8


def plan_episodes(suite: str, tasks: Iterable[Mapping[str, Any]], episodes_per_task: int, seed: int = 0,
                  horizon: int | None = None) -> list[DotEpisode]:
    out = []
    for i, task in enumerate(tasks):
        out += [DotEpisode(suite, str(task["task"]), seed + i * episodes_per_task + k, horizon or MAX_STEPS,
                           f"move to the {task['task']} dot") for k in range(episodes_per_task)]
    return out


def episode_problems(episode: DotEpisode, tasks: Iterable[Mapping[str, Any]]) -> list[str]:
    names = [t["task"] for t in tasks]
    return [] if episode.task in names else [f"task {episode.task!r}: the suite's tasks are {names}"]


class DotEnv:
    """The suite's env: ``tasks``, ``reset``, ``step``, ``close``, ``alive``."""

    alive = True

    def __init__(self, options: DotOptions) -> None:
        self.size = options.image_size

    def tasks(self, suite: str) -> list[dict[str, Any]]:
        return [{"task_id": i, "task": name, "instruction": f"move to the {name} dot"} for i, name in enumerate(TASKS)]

    def reset(self, episode: DotEpisode) -> dict[str, Any]:
        self.x = float(np.random.default_rng(episode.seed).uniform(0.0, 1.0))
        self.target = TARGETS[episode.task]
        return self._observation()

    def step(self, action: np.ndarray, images: bool = True) -> dict[str, Any]:
        self.x = float(np.clip(self.x + SPEED * float(np.clip(action[0], -1.0, 1.0)), 0.0, 1.0))
        reached = abs(self.x - self.target) < REACH
        return {"observation": self._observation(), "reward": float(reached), "terminated": reached,
                "success": reached}

    def close(self) -> None:
        pass

    def _observation(self) -> dict[str, Any]:
        frame = np.zeros((self.size, self.size, 3), np.uint8)
        frame[:, min(int(self.target * self.size), self.size - 1), 1] = 255
        frame[:, min(int(self.x * self.size), self.size - 1), 0] = 255
        return {"image": frame, "state": np.array([self.x], np.float32)}


def observation(obs: Mapping[str, Any], step: int) -> dict[str, Any]:
    return {"images": {"top": obs["image"]}, "qpos": {"point": obs["state"]}, "prompt": obs["task"], "step": step}


def layout(options: DotOptions) -> DatasetLayout:
    return DatasetLayout(
        image_size=options.image_size, cameras=(("top", "observation.image", "the line, the point and the dot"),),
        move_group="point", state=Vector("observation.state", 1, None, "the point's position on [0, 1]"),
        action=Vector("action", 1, None, "the point's velocity command in [-1, 1]"),
        robot_type="point", fps=10, step_hz=10.0, outcomes=tuple(OUTCOMES), simulator="one line of numpy")


DOT: SuiteKind[DotOptions] = SuiteKind(
    name="dot", episode=DotEpisode, plan=plan_episodes, open=DotEnv, task_label=lambda e: f"dot/{e.task}",
    observation=observation, move_group="point", action_dim=1, control_hz=10, cameras={"top": "observation.image"},
    frame_size=lambda o: o.image_size, options=DotOptions, action_extra={"action_bounds": {"point": (-1.0, 1.0)}},
    benchmarks={"dot_reach": MAX_STEPS},
    check_episode=episode_problems, distributions=("molmo-example-suite",), recording=layout, robot="point")


@hookimpl
def molmo_benchmark_kinds() -> list[EnvSuiteKind[DotOptions]]:
    return [EnvSuiteKind(DOT)]
