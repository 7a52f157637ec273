"""Build a policy instance from the resolved ``policy`` config group."""

from __future__ import annotations

from typing import Any

from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import Policy
from molmo_lerobot.policies.convention import ConventionAdapter, get_convention


def make_policy(plugins: Plugins, policy_cfg: dict[str, Any]) -> Policy:
    """Look the policy plugin up in ``plugins`` by ``policy_cfg["name"]`` and call its factory;
    ``policy.convention`` goes to plugins that read it (``PolicyType.conventions``), else wraps the policy."""
    policy_type = plugins.policy(str(policy_cfg["name"]))
    cfg = dict(policy_cfg)
    convention = get_convention(str(cfg.get("convention") or "native"))
    if not policy_type.conventions:
        cfg.pop("convention", None)
    policy = policy_type.factory(cfg)
    if not isinstance(policy, Policy):
        raise TypeError(f"policy plugin {policy_type.name!r} built {type(policy).__name__}, not a Policy")
    if convention.name != "native" and not policy_type.conventions:
        policy = ConventionAdapter(policy, convention)
    return policy
