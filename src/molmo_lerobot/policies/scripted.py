"""``policy=scripted`` (a policy plugin) and the scripted experts it dispatches to (hook ``molmo_experts``).

The experts: :mod:`.scripted_pick`, :mod:`.scripted_place`, :mod:`.scripted_articulated`;
what they share is in :mod:`.expert_motion`. MetaWorld's own experts: :mod:`.scripted_metaworld`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from molmo_lerobot import hookimpl
from molmo_lerobot.options import validate_group
from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyType
from molmo_lerobot.policies.expert_options import ScriptedOptions
from molmo_lerobot.policies.scripted_articulated import ScriptedArticulated
from molmo_lerobot.policies.scripted_metaworld import metaworld_experts
from molmo_lerobot.policies.scripted_pick import ScriptedPick
from molmo_lerobot.policies.scripted_place import ScriptedPlace


class ScriptedExpert(Policy):
    """``policy=scripted``: each episode is played by the expert registered for its task type.

    Experts register through the ``molmo_experts`` hook (a PolicyType named after the task
    type it serves); this policy only dispatches, keeping one expert instance per task type.
    """

    needs_images = False
    needs_simulator = True

    def __init__(self, config: Mapping[str, Any]) -> None:
        self.config = validate_group("policy", ScriptedOptions, config).model_dump()  # what each expert gets
        self.experts: dict[str, Policy] = {}
        self.current: Policy | None = None

    def reset(self, ctx: EpisodeContext) -> None:
        if ctx.env is None and "suite" not in ctx.extra:  # an env suite's episode: its env in ``extra``
            raise ValueError("scripted policy needs privileged simulator access (EpisodeContext.env)")
        if ctx.expert is None:
            task = ctx.spec.task_name if ctx.spec else None
            raise ValueError(f"scripted policy: no scripted expert serves task type {task!r}")
        if ctx.expert.name not in self.experts:
            self.experts[ctx.expert.name] = ctx.expert.factory(self.config)
        self.current = self.experts[ctx.expert.name]
        self.current.reset(ctx)

    def act(self, obs: Observation) -> Action:
        if self.current is None:
            raise RuntimeError("scripted policy: act() before reset()")
        return self.current.act(obs)

    def close(self) -> None:
        for expert in self.experts.values():
            expert.close()


@hookimpl
def molmo_experts() -> list[PolicyType]:
    return [PolicyType(name="pick", factory=ScriptedPick, description="grasp library + IK, lift"),
            PolicyType(name="pick_and_place", aliases=("pick_and_place_next_to", "pick_and_place_color"),
                       factory=ScriptedPlace, description="pick, carry, place, release"),
            PolicyType(name="open", aliases=("close",), factory=ScriptedArticulated,
                       description="grasp the handle, move it along the joint"),
            *metaworld_experts()]


@hookimpl
def molmo_policies() -> list[PolicyType]:
    return [PolicyType(name="scripted", factory=ScriptedExpert,
                       description="privileged expert of each episode's task type (IK + grasp library)",
                       options=ScriptedOptions)]
