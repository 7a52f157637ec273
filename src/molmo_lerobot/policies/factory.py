"""Build a policy instance from the resolved ``policy`` config group, validated by its plugin's model."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from molmo_lerobot.options import validate_group
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import Policy, PolicyOptions
from molmo_lerobot.policies.convention import ConventionAdapter, get_convention


def policy_options(plugins: Plugins, policy_cfg: Mapping[str, Any]) -> PolicyOptions:
    """``policy_cfg`` validated by the options model of the policy plugin it names in ``plugins``
    (:attr:`~molmo_lerobot.policies.base.PolicyType.options`); an
    :class:`~molmo_lerobot.options.OptionsError` names each bad ``policy.<key>``."""
    return validate_group("policy", plugins.policy(str(policy_cfg["name"])).options, policy_cfg)


def make_policy(plugins: Plugins, policy_cfg: Mapping[str, Any]) -> Policy:
    """Look the policy plugin up in ``plugins`` by ``policy_cfg["name"]`` and call its factory with its
    validated options as a plain dict; ``policy.convention`` goes to plugins that read it
    (``PolicyType.conventions``), else wraps the policy."""
    policy_type = plugins.policy(str(policy_cfg["name"]))
    options = validate_group("policy", policy_type.options, policy_cfg)
    convention = get_convention(options.convention)
    policy = policy_type.factory(options.model_dump(exclude=set() if policy_type.conventions else {"convention"}))
    if not isinstance(policy, Policy):
        raise TypeError(f"policy plugin {policy_type.name!r} built {type(policy).__name__}, not a Policy")
    if convention.name != "native" and not policy_type.conventions:
        policy = ConventionAdapter(policy, convention)
    return policy
