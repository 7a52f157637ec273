"""MetaWorld's scripted experts (``metaworld.policies``, one per task) as ``policy=scripted`` on MetaWorld benchmarks.

Each serves the task type ``metaworld/<task>`` (the MetaWorld suite's task label) and is the class LeRobot's
``MetaworldEnv`` names for the task (``TASK_POLICY_MAPPING`` of its ``metaworld_config.json``). An expert acts on
MetaWorld's full 39-D observation, which it reads from the suite env of its context (``ctx.extra["suite"]``'s
``raw_observation``), one 4-D action a step.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Any

import numpy as np

from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyType

#: the task type prefix of MetaWorld's episodes
LABEL_PREFIX = "metaworld/"


def lerobot_metaworld_config() -> dict[str, Any]:
    """LeRobot's ``envs/metaworld_config.json`` (task descriptions, groups, expert classes), read without importing
    LeRobot or MetaWorld; ``{}`` where LeRobot is not installed. The MetaWorld suite's catalogue is read from it too."""
    spec = importlib.util.find_spec("lerobot")
    if spec is None or not spec.submodule_search_locations:
        return {}
    path = Path(next(iter(spec.submodule_search_locations))) / "envs" / "metaworld_config.json"
    return dict(json.loads(path.read_text())) if path.is_file() else {}


def _expert_classes() -> dict[str, str]:
    """Task -> the ``metaworld.policies`` class LeRobot maps it to."""
    return dict(lerobot_metaworld_config().get("TASK_POLICY_MAPPING", {}))


class MetaWorldExpert(Policy):
    """The scripted expert of the episode's MetaWorld task (its context's ``expert.name``)."""

    needs_images = False
    needs_simulator = True

    def __init__(self, config: dict[str, Any]) -> None:
        self.config = config
        self.suite: Any = None
        self.policy: Any = None
        self.group = ""

    def reset(self, ctx: EpisodeContext) -> None:
        import metaworld.policies

        if ctx.expert is None or "suite" not in ctx.extra:
            raise ValueError("MetaWorld expert: needs the episode's MetaWorld env (a metaworld_* benchmark)")
        task = ctx.expert.name.removeprefix(LABEL_PREFIX)
        self.policy = getattr(metaworld.policies, _expert_classes()[task])()
        self.suite, self.group = ctx.extra["suite"], next(iter(ctx.move_groups))

    def act(self, obs: Observation) -> Action:
        action = np.asarray(self.policy.get_action(self.suite.raw_observation), dtype=np.float32)
        return {self.group: action[None]}


def metaworld_experts() -> list[PolicyType]:
    """One expert per MetaWorld task LeRobot knows."""
    return [PolicyType(name=f"{LABEL_PREFIX}{task}", factory=MetaWorldExpert,
                       description=f"MetaWorld's {cls} (metaworld.policies)")
            for task, cls in _expert_classes().items()]
