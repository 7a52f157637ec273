"""Build a policy instance from the resolved ``policy`` config group."""

from __future__ import annotations

from typing import Any

from molmo_lerobot.plugins import get_plugins
from molmo_lerobot.policies.base import Policy


def make_policy(policy_cfg: dict[str, Any]) -> Policy:
    """Look the policy plugin up by ``policy_cfg["name"]`` and call its factory."""
    policy_type = get_plugins().policy(str(policy_cfg["name"]))
    policy = policy_type.factory(dict(policy_cfg))
    if not isinstance(policy, Policy):
        raise TypeError(f"policy plugin {policy_type.name!r} built {type(policy).__name__}, not a Policy")
    return policy
