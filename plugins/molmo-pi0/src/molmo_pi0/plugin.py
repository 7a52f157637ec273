"""Entry point ``pi0`` in the ``molmo_lerobot`` group: the policy and its Hydra config."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from molmo_lerobot import hookimpl
from molmo_lerobot.policies.base import Policy, PolicyType
from molmo_pi0.policy import Pi0Config


def make_pi0_policy(cfg: dict[str, Any]) -> Policy:
    """Remote mode unless ``policy.path`` is set (then LeRobot's PI0 in this process); LIBERO requests with
    ``policy.protocol=libero`` (``policy=pi0_libero``)."""
    from molmo_pi0.policy import Pi0InProcessPolicy, Pi0RemotePolicy

    if cfg.get("protocol") == "libero":
        from molmo_pi0.libero import Pi0LiberoPolicy

        return Pi0LiberoPolicy(cfg)
    return Pi0InProcessPolicy(cfg) if cfg.get("path") else Pi0RemotePolicy(cfg)


@hookimpl
def molmo_policies() -> list[PolicyType]:
    return [PolicyType("pi0", make_pi0_policy, "pi0 / pi0.5: openpi server (DROID keys) or LeRobot PI0 (policy.path); "
                       "presets policy=pi0 (MolmoSpaces' eval config), "
                       "policy=pi0_droid (openpi's velocity checkpoints), "
                       "policy=pi0_libero (openpi's LIBERO checkpoints)",
                       conventions=True, options=Pi0Config)]


@hookimpl
def molmo_config_dirs() -> list[str]:
    return [str(Path(__file__).resolve().parent / "conf")]
