"""The pi0 policy in its two modes: remote (openpi protocol, DROID keys) and in process (LeRobot PI0).

Which checkpoints each preset fits: :mod:`molmo_pi0.droid`.
"""

from __future__ import annotations

import copy
from typing import Any, Literal

import numpy as np
from pydantic import Field

from molmo_lerobot.options import validate_group
from molmo_lerobot.policies.base import Action, ConventionName, EpisodeContext, Observation, Policy, PolicyOptions
from molmo_lerobot.policies.convention import get_convention
from molmo_lerobot.protocol.client import PolicyClient
from molmo_pi0.droid import (
    ACTIONS,
    JOINTS,
    CameraConfig,
    DroidConfig,
    check_checkpoint,
    droid_actions,
    droid_request,
)


class Pi0Config(DroidConfig, PolicyOptions):
    """The ``policy`` group for ``policy=pi0`` (see conf/policy/pi0.yaml)."""

    name: str = "pi0"
    convention: ConventionName = "molmospaces"
    #: MolmoSpaces' PI_Policy's picks, then our benchmarks' names (the first present)
    cameras: CameraConfig = Field(default_factory=lambda: CameraConfig(
        exterior=["droid_shoulder_light_randomization", "exo_camera_1", "exterior"],
        wrist=["wrist_camera_zed_mini", "wrist_camera", "wrist"]))
    #: the request's keys: openpi's DROID client's (droid.py) or its LIBERO client's (libero.py, policy=pi0_libero)
    protocol: Literal["droid", "libero"] = "droid"
    host: str = "127.0.0.1"
    port: int | None = Field(default=8000, ge=0, le=65535)
    api_key: str | None = None
    path: str | None = None
    device: str = "auto"
    timeout_s: float = Field(default=120.0, gt=0)
    connect_timeout_s: float = Field(default=60.0, ge=0)
    max_message_bytes: int = Field(default=64 * 2**20, ge=1024)
    reset: Literal["none", "message", "reconnect"] = "none"
    inprocess_cameras: dict[str, str] = Field(default_factory=dict)
    inprocess_state: list[str] = Field(default_factory=lambda: ["arm", "gripper"])
    checkpoint: str | None = None  # the served checkpoint (name or path), recorded and checked against action_mode
    end_on_success: bool = True    # read by the run (top-level end_on_success follows it), not by the policy


class OpenpiClientPolicy(Policy):
    """A client of an openpi server (``serve_policy``, or ``molmo-serve``): one websocket connection per policy
    instance (= per worker), reset as ``policy.reset`` says; subclasses make the request and read the answer."""

    cfg: Pi0Config

    def _open_client(self) -> None:
        self.client = PolicyClient(
            self.cfg.host,
            self.cfg.port,
            timeout_s=self.cfg.timeout_s,
            connect_timeout_s=self.cfg.connect_timeout_s,
            max_message_bytes=self.cfg.max_message_bytes,
            api_key=self.cfg.api_key,
        )
        self._ctx: EpisodeContext | None = None

    def reset(self, ctx: EpisodeContext) -> None:
        self._ctx = ctx
        if self.cfg.reset == "reconnect" or not self.client.connected:
            self.client.connect()
        if self.cfg.reset == "message":
            self.client.reset(prompt=ctx.prompt, episode_index=ctx.episode_index, seed=ctx.seed)

    def _infer_actions(self, request: dict[str, Any]) -> Any:
        """The server's ``actions`` for ``request`` (an answer without them is an error naming its keys)."""
        response = self.client.infer(request)
        if ACTIONS not in response:
            raise ValueError(f"policy server {self.client.uri} answered without 'actions' (keys: {sorted(response)})")
        return response[ACTIONS]

    def close(self) -> None:
        self.client.close()


class Pi0RemotePolicy(OpenpiClientPolicy):
    """openpi's DROID protocol; chunk length from the response."""

    def __init__(self, cfg: dict[str, Any]) -> None:
        self.cfg = validate_group("policy", Pi0Config, cfg)
        check_checkpoint(self.cfg.checkpoint, self.cfg.action_mode)
        self.convention = get_convention(self.cfg.convention)
        self._open_client()

    def act(self, obs: Observation) -> Action:
        assert self._ctx is not None, "reset() must be called before act()"
        view = self.convention.observation(obs)
        request = droid_request(self.convention.images(view), view.get("qpos") or {},
                                obs.get("prompt") or self._ctx.prompt, self.cfg)
        return droid_actions(self._infer_actions(request), request[JOINTS], self.cfg, self._ctx.policy_dt_s,
                             f"policy server {self.client.uri}")


class Pi0InProcessPolicy(Policy):
    """LeRobot's PI0 (or any LeRobot checkpoint emitting DROID-style actions) in this process.

    Its inputs follow the checkpoint's LeRobot features (``inprocess_cameras``, ``inprocess_state``);
    the preset's action side (``action_mode``, ``open_loop_horizon``, ``gripper``) applies as remote.
    A checkpoint of :mod:`molmo_pi0.random_init` at a scaled size is built at its recorded size.
    Served (``policy.serve=true``, ``molmo-serve``), clients are forks of one model and their
    requests run as one batched forward (:meth:`act_batch`).
    """

    def __init__(self, cfg: dict[str, Any]) -> None:
        self.cfg: Pi0Config = validate_group("policy", Pi0Config, cfg)
        check_checkpoint(self.cfg.path, self.cfg.action_mode)
        from molmo_lerobot.policies.lerobot_policy import LeRobotPolicy
        from molmo_pi0.random_init import read_dims, scaled_architecture

        try:
            kind, dims = read_dims(self.cfg.path) or ("pi0", None)  # type: ignore[arg-type]
            with scaled_architecture(kind, dims):
                self.inner = LeRobotPolicy({
                    "name": "pi0", "path": self.cfg.path, "device": self.cfg.device, "mode": "chunk",
                    "cameras": self.cfg.inprocess_cameras, "state": self.cfg.inprocess_state,
                    "verify_weights": True,
                })
        except ImportError as exc:
            raise ImportError(f"policy=pi0 policy.path=… needs `pip install molmo-pi0[inprocess]` ({exc})") from exc
        self.needs_images = self.inner.needs_images
        self.batched = self.inner.batched
        self._ctx: EpisodeContext | None = None

    def reset(self, ctx: EpisodeContext) -> None:
        self._ctx = ctx
        self.inner.reset(ctx)

    def act(self, obs: Observation) -> Action:
        assert self._ctx is not None, "reset() must be called before act()"
        return self._actions(self.inner.predict(obs), obs)

    def _actions(self, raw: np.ndarray, obs: Observation) -> Action:
        arm = np.asarray(obs["qpos"]["arm"], dtype=np.float64)
        return droid_actions(raw, arm, self.cfg, self._ctx.policy_dt_s,  # type: ignore[union-attr]
                             f"pi0 checkpoint {self.cfg.path!r}")

    def fork(self) -> Pi0InProcessPolicy | None:
        """A client of the same model (its own episode state), for batched serving."""
        inner = self.inner.fork()
        if inner is None:
            return None
        twin = copy.copy(self)
        twin.inner, twin._ctx = inner, None
        return twin

    @classmethod
    def act_batch(cls, policies: list[Policy], observations: list[Observation]) -> list[Action | Exception]:
        """One forward of the shared model for all clients; each answer mapped as :meth:`act` maps it."""
        from molmo_lerobot.policies.lerobot_policy import LeRobotPolicy

        forks: list[Pi0InProcessPolicy] = policies  # type: ignore[assignment]
        raws = LeRobotPolicy.predict_batch([p.inner for p in forks], observations)
        results: list[Action | Exception] = []
        for p, obs, raw in zip(forks, observations, raws, strict=True):
            if isinstance(raw, Exception):
                results.append(raw)
            elif p._ctx is None:
                results.append(RuntimeError("reset() must be called before act()"))
            else:
                try:
                    results.append(p._actions(raw, obs))
                except Exception as exc:  # one client's bad answer fails its own request only
                    results.append(exc)
        return results

    def close(self) -> None:
        self.inner.close()
