"""The policy interface: reset once per episode, then act on observations.

Observation (a plain dict, so it crosses process and network boundaries unchanged)::

    {
      "images": {camera_name: uint8 array (H, W, 3)},      # only if the policy wants images
      "depth":  {camera_name: float32 array (H, W)},       # cameras with record_depth
      "qpos":   {move_group: float array},                 # e.g. {"arm": (7,) rad, "gripper": (1,)}
      "qvel":   {move_group: float array},                 # gripper: 0 open … 1 closed (and per second)
      "tcp_pose": float array (7,),                        # x, y, z, qw, qx, qy, qz in world
      "robot_base_pose": float array (7,),                 # the robot base's world pose, same layout
      "joint_qpos": {move_group: float array},             # joints in their own units (rad, m): the gripper's
      "joint_qvel": {move_group: float array},             #   as MolmoSpaces lists them (Robotiq: 2 driver angles)
      "environment_state": float32 array,                  # only for a policy or run that asks: the task's
                                                           #   privileged ground truth (features.ENV_STATE)
      "prompt": str,                                       # the episode's language instruction
      "step": int,                                         # policy step index in the episode
    }

Action: a dict keyed by move group, ``{"arm": (7,) joint positions, "gripper": (1,)}``. A
*chunk* is the same dict with a leading time axis, ``{"arm": (H, 7), "gripper": (H, 1)}``;
chunks run open loop. This is the *native* convention (DROID's and LeRobot's units); a policy
configured with ``convention: molmospaces`` sees MolmoSpaces' keys, units and frames instead
(:mod:`molmo_lerobot.policies.convention`). Native:

* **gripper**: one value normalized to [0, 1], **0 = open, 1 = closed**, in the action and in
  the observed ``qpos["gripper"]`` (so ``observation.state``'s last entry) alike. Each robot maps
  it linearly onto its gripper's full travel: the Panda hand's finger positions (0.04 … 0 m),
  the Robotiq 2F-85's actuator (0 … 255, driver joints 0 … 0.8 rad).
* **a left-out move group holds its position** (its current target), as in MolmoSpaces; a key
  that is neither a move group nor ``done`` is an error.
* **``done``** (optional): ``True`` ends the episode after that step (one bool per chunk step, or
  one bool for the chunk's last step). With ``end_on_success: true`` in the run config the
  episode also ends at its first successful step. Both are recorded per episode
  (``episodes.jsonl`` ``extra.ended_by``: ``horizon`` / ``done`` / ``success``).

The rollout loop validates every action (keys, shapes, finite values) and turns a bad one
into a per-episode error that names the policy, the move group and what was wrong.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from molmo_lerobot.assets.catalog import AssetCatalog
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env

Observation = dict[str, Any]
Action = dict[str, np.ndarray]


class PlannedEpisode(Protocol):
    """What a context reads of an episode's plan (:class:`~molmo_lerobot.episode_plan.EpisodePlan`)."""

    @property
    def episode_index(self) -> int: ...

    @property
    def seed(self) -> int: ...

    @property
    def prompt(self) -> str: ...


@dataclass
class EpisodeContext:
    """What a policy learns at reset.

    ``env`` (privileged simulator access), ``catalog`` (the run's asset catalog: grasps, object
    annotations) and ``expert`` (the scripted expert the plugins register for the episode's task
    type, if any) are set only for policies that declare :attr:`Policy.needs_simulator`
    (scripted experts); a policy under evaluation gets ``None``.
    """

    spec: EpisodeSpec | None  # None for an env suite's episode (LIBERO: no scene of ours)
    episode_index: int
    seed: int
    prompt: str
    move_groups: dict[str, int]
    policy_dt_s: float
    env: Env | None = None
    catalog: AssetCatalog | None = None
    expert: PolicyType | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def of_plan(cls, plan: PlannedEpisode, move_groups: dict[str, int], policy_dt_s: float, *,
                spec: EpisodeSpec | None = None, **privileged: Any) -> EpisodeContext:
        """The context of planned episode ``plan`` (its index, seed and prompt), as every session builds it;
        ``privileged``: ``env``, ``catalog``, ``expert`` (scripted experts only) and ``extra``."""
        return cls(spec=spec, episode_index=plan.episode_index, seed=plan.seed, prompt=plan.prompt,
                   move_groups=dict(move_groups), policy_dt_s=policy_dt_s, **privileged)


class Policy(ABC):
    """A policy instance. One instance serves one worker, episodes in sequence."""

    #: Whether ``act`` needs camera images. Policies that do not (scripted experts) let the
    #: environment skip rendering unless a recorder asks for frames.
    needs_images: bool = True
    #: Whether ``act`` reads ``obs["environment_state"]``, the task's privileged ground truth
    #: (:mod:`molmo_lerobot.features`): the rollout then adds it to every observation.
    needs_environment_state: bool = False
    #: Whether the policy reads the simulator (``EpisodeContext.env``): privileged scripted experts.
    #: The runner hands the environment to no other policy; ``molmo-serve`` refuses such a
    #: policy (a server has no simulator).
    needs_simulator: bool = False
    #: Whether :meth:`act_batch` may serve this instance (``molmo-serve max_batch=N``).
    batched: bool = False

    @abstractmethod
    def reset(self, ctx: EpisodeContext) -> None:
        """Start a new episode. Must clear every per-episode state."""

    @abstractmethod
    def act(self, obs: Observation) -> Action:
        """Return one action or a chunk of actions (leading time axis) for ``obs``."""

    def close(self) -> None:  # noqa: B027 - optional hook: does nothing unless overridden
        """Release resources (connections, GPU memory). Called once when the worker ends."""

    def fork(self) -> Policy | None:
        """Optional: a new instance with its own per-episode state that shares this one's model
        (weights loaded once), for serving many clients. ``None`` (the default): the server
        builds a fresh instance per client."""
        return None

    @classmethod
    def act_batch(cls, policies: list[Policy], observations: list[Observation]) -> list[Action | Exception]:
        """Optional batched ``act`` for ``molmo-serve`` (used when :attr:`batched` is true).

        ``policies[i]`` is client i's instance (forks of one policy: its own episode state, one
        shared model), ``observations[i]`` its observation. Returns one entry per client: its
        action, or the exception its item raised, which fails only that client's request. A
        client whose entry is an exception must keep its state; if the whole call raises, the
        server retries each item alone.
        """
        raise NotImplementedError(f"{cls.__name__} has no batched act")


@dataclass(frozen=True)
class PolicyType:
    """A policy plugin's descriptor.

    ``factory(config)`` builds a :class:`Policy` from the resolved ``policy`` config group
    (a plain dict). It runs inside each worker process, so it must be picklable by name
    (a module-level function or class).
    """

    name: str
    factory: Callable[[dict[str, Any]], Policy]
    description: str = ""
    aliases: tuple[str, ...] = ()
    #: The factory reads ``policy.convention`` itself (its boundary is a wire, a state vector or a
    #: request, not the observation dict). Otherwise ``policy.convention`` is taken out of the config
    #: and a non-native one wraps the policy: it acts on that convention's view of each observation
    #: and returns that convention's actions (:class:`~molmo_lerobot.policies.convention.ConventionAdapter`).
    conventions: bool = False
    #: Modules its policies import when built (lazily, past the factory's own module): a worker's
    #: fork server imports them once for every worker (``executor.start_method=forkserver``).
    preload: tuple[str, ...] = ()
    #: ``check(config)``: the ``policy`` config's problems, one line each naming its key
    #: (``policy.chunk: ...``), checked before any run directory is made; ``None``: none checked
    #: up front (the factory checks its config when a worker builds the policy).
    check: Callable[[dict[str, Any]], list[str]] | None = None


#: Most action steps one chunk may hold (``policy.chunk``): past it a chunk allocates gigabytes.
MAX_CHUNK = 10_000


def option_problems(config: dict[str, Any], bounds: dict[str, tuple[float, float, bool]]) -> list[str]:
    """Problems of ``config``'s numeric options: ``bounds`` maps a key to ``(low, high, integer)``;
    an absent key takes the policy's default and is not checked."""
    out = []
    for key, (low, high, integer) in bounds.items():
        if key not in config:
            continue
        value = config[key]
        kind = "an integer" if integer else "a number"
        ok = (isinstance(value, int) if integer else isinstance(value, int | float)) and not isinstance(value, bool)
        if not (ok and math.isfinite(value) and low <= value <= high):
            out.append(f"policy.{key}: expected {kind} in {low:g}..{high:g}, got {value!r}")
    return out
