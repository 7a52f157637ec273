"""``policy=remote policy.host=… policy.port=…``: any policy served by ``molmo-serve``, over the wire.

The client side of :mod:`molmo_lerobot.serving.server`: observations travel in the native
format unchanged, each episode starts with a reset message (episode index, seed, prompt,
move groups, policy period), so the served policy sees what it would see in process and a
deterministic policy gives the same outcomes. Timeouts, connect retries with backoff and
reconnects are the pi0 client's (:class:`~molmo_lerobot.protocol.client.PolicyClient`); a
connection lost between episodes is re-opened at the next reset, one lost mid-episode fails
that episode (the served policy's episode state is gone). ``policy.convention=molmospaces``
sends MolmoSpaces' observation layout instead and reads MolmoSpaces' actions back
(:mod:`molmo_lerobot.policies.convention`). ``policy.transport=shm policy.socket=@…`` talks to a
server on this machine over shared memory instead (:mod:`molmo_lerobot.protocol.shm`; what
``policy.serve=true`` hands its workers), with the same messages and the same behaviour.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

from pydantic import Field

from molmo_lerobot.hookspecs import hookimpl
from molmo_lerobot.options import validate_group
from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy, PolicyOptions, PolicyType
from molmo_lerobot.policies.convention import get_convention
from molmo_lerobot.protocol.client import PolicyClient, PolicyConnectionError
from molmo_lerobot.protocol.shm import ShmPolicyClient


class RemoteOptions(PolicyOptions):
    """``policy=remote``'s options (conf/policy/remote.yaml documents them)."""

    name: str = "remote"
    host: str = "127.0.0.1"
    port: int | None = Field(default=8000, ge=0, le=65535)
    api_key: str | None = None
    timeout_s: float = Field(default=120.0, gt=0)
    connect_timeout_s: float = Field(default=60.0, ge=0)
    max_message_bytes: int = Field(default=64 * 2**20, ge=1024)
    transport: Literal["websocket", "shm"] = "websocket"
    socket: str | None = None  # with transport=shm: the server's socket address (@name: abstract)


class RemotePolicy(Policy):
    """One connection per instance (= per worker), opened at construction to read the metadata."""

    def __init__(self, cfg: Mapping[str, Any]) -> None:
        self.cfg = validate_group("policy", RemoteOptions, cfg)
        self.convention = get_convention(self.cfg.convention)
        self.client: PolicyClient | ShmPolicyClient
        if self.cfg.transport == "shm":
            if not self.cfg.socket:
                raise ValueError("policy=remote: policy.transport=shm needs policy.socket (the server's address)")
            self.client = ShmPolicyClient(self.cfg.socket, timeout_s=self.cfg.timeout_s,
                                          connect_timeout_s=self.cfg.connect_timeout_s,
                                          max_message_bytes=self.cfg.max_message_bytes)
        else:
            self.client = PolicyClient(self.cfg.host, self.cfg.port, timeout_s=self.cfg.timeout_s,
                                       connect_timeout_s=self.cfg.connect_timeout_s,
                                       max_message_bytes=self.cfg.max_message_bytes, api_key=self.cfg.api_key)
        metadata = self.client.connect()
        if metadata.get("server") != "molmo-serve":
            self.client.close()
            raise ValueError(f"policy=remote: {self.client.uri} is not a molmo-serve server (metadata "
                             f"{sorted(metadata)[:8]}); for an openpi server use policy=pi0")
        self.served = str(metadata.get("policy"))
        self.needs_images = bool(metadata.get("needs_images", True))
        #: a served policy trained on ``observation.environment_state`` gets it sent, as in process
        self.needs_environment_state = bool(metadata.get("needs_environment_state", False))
        self._connects = -1

    def reset(self, ctx: EpisodeContext) -> None:
        self.client.reset(episode_index=ctx.episode_index, seed=ctx.seed, prompt=ctx.prompt,
                          move_groups=dict(ctx.move_groups), policy_dt_s=ctx.policy_dt_s)
        self._connects = self.client.connects

    def act(self, obs: Observation) -> Action:
        if self._connects < 0:
            raise RuntimeError("policy=remote: act() before reset()")
        response = self.client.infer(self.convention.observation(obs))
        if self.client.connects != self._connects:
            self._connects = -1
            raise PolicyConnectionError(f"policy server {self.client.uri} dropped the connection mid-episode; the "
                                        "served policy's episode state is lost (the next episode reconnects)")
        response.pop("server_timing", None)
        return self.convention.action(response)

    def close(self) -> None:
        self.client.close()


@hookimpl
def molmo_policies() -> list[PolicyType]:
    return [PolicyType("remote", RemotePolicy, "any policy served by molmo-serve (policy.host=… policy.port=…)",
                       conventions=True, options=RemoteOptions)]
