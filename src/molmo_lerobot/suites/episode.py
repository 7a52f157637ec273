"""What every env suite's episode spec is (:class:`~molmo_lerobot.suites.libero.LiberoEpisode`,
:class:`~molmo_lerobot.suites.pusht.PushTEpisode`): a frozen dataclass whose identity is its content; and the
episodes of suites whose tasks are gym env ids, each seeded ``seed + k`` (:class:`TaskEpisode`: PushT's, ALOHA's)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

from molmo_lerobot.hashing import content_sha256


class SuiteEpisode:
    """Base of an env suite's frozen episode dataclass: :attr:`digest` is its identity."""

    @property
    def digest(self) -> str:
        """SHA-256 of the episode's canonical JSON (keys sorted, ASCII escapes)."""
        fields: Any = asdict(self)  # type: ignore[call-overload]  # subclasses are dataclasses
        return content_sha256(fields, ensure_ascii=True).hex()


@dataclass(frozen=True)
class TaskEpisode(SuiteEpisode):
    """An episode of a suite whose tasks are named gym envs (PushT's, ALOHA's): one task, its seed and horizon,
    the prompt ``lerobot-eval`` gives the policy."""

    suite: str
    task: str
    seed: int
    horizon: int
    instruction: str


def plan_task_episodes[EpisodeT: TaskEpisode](episode: type[EpisodeT], suite: str, tasks: Iterable[Mapping[str, Any]],
                                             episodes_per_task: int, seed: int, horizon: int) -> list[EpisodeT]:
    """``episodes_per_task`` episodes of each task (the catalogue's ``task`` and ``instruction``), episode ``k``
    seeded ``seed + k`` (``lerobot-eval``'s with ``--eval.batch_size=1``), each ``horizon`` steps long."""
    return [episode(suite, str(task["task"]), seed + k, horizon, str(task["instruction"]))
            for task in tasks for k in range(episodes_per_task)]


def task_episode_problems(episode: TaskEpisode, tasks: Iterable[Mapping[str, Any]], owner: str) -> list[str]:
    """What is wrong with ``episode`` against the catalogue: a task ``owner`` has, with its instruction."""
    by_name = {str(task["task"]): task for task in tasks}
    task = by_name.get(episode.task)
    if task is None:
        return [f"task {episode.task!r}: {owner}'s tasks are {', '.join(map(repr, by_name))}"]
    if episode.instruction != task["instruction"]:
        return [f"instruction {episode.instruction!r}: task {episode.task}'s is {task['instruction']!r}"]
    return []


def task_label(episode: TaskEpisode) -> str:
    """The episode's ``per_task`` key, ``<suite>/<task>``: ``pusht/PushT-v0``, ``aloha_insertion/AlohaInsertion-v0``."""
    return f"{episode.suite}/{episode.task}"
