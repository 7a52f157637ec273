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

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Annotated, Any, Literal, Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict

from molmo_lerobot.options import is_int, is_number, optional, rule

if TYPE_CHECKING:
    from molmo_lerobot.assets.catalog import AssetCatalog
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.sim.env import Env

Observation = dict[str, Any]
Action = dict[str, np.ndarray]
#: the observation and action layouts a policy may work in (:mod:`molmo_lerobot.policies.convention`)
ConventionName = Literal["native", "molmospaces"]


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


#: Bounds of the serving keys every policy has (``policy.serve*``)
MAX_SERVE_BATCH = 4096
MAX_SERVE_BATCH_TIMEOUT_MS = 60_000
SERVE_TRANSPORTS = ("auto", "shm", "websocket")
#: Most action steps one chunk may hold (``policy.chunk``): past it a chunk allocates gigabytes.
MAX_CHUNK = 10_000


class PolicyOptions(BaseModel):
    """A policy's options: the ``policy`` config group (``conf/policy/<name>.yaml``, ``policy.<key>=``).

    The keys every policy shares are here; a policy plugin subclasses it with its own
    (:attr:`PolicyType.options`), each default stated once, in the model (a yaml may repeat it, never
    differ: ``tests/policies/test_policy_options.py``). Unknown keys are refused unless the subclass
    allows them (``model_config = ConfigDict(extra="allow")``). The run validates its ``policy`` group
    with the model before any output is written; the factory gets the result as a plain dict.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    #: the plugin (``policy=<name>``)
    name: Annotated[str, rule(lambda v: isinstance(v, str) and v != "",
                              "{key}: expected the policy's name (policy=<name>), got {got}")]
    #: native | molmospaces: the observation and action layout the policy works in (policies.convention)
    convention: ConventionName = "native"
    #: where the policy's model runs (auto | cpu | cuda | cuda:N | mps); null: it has none (the
    #: worker places a policy that says auto or cuda on one of ``executor.cuda_devices``)
    device: str | None = None
    #: one local molmo-serve for the run (executor=ray: one per node), the workers its clients
    serve: Annotated[bool, rule(lambda v: isinstance(v, bool), "{key}: expected true or false, got {got}")] = False
    #: with serve: requests per batched forward (null: the number of workers)
    serve_max_batch: Annotated[int | None, rule(
        optional(lambda v: is_int(v) and 1 <= v <= MAX_SERVE_BATCH),
        f"{{key}}: expected an integer in 1..{MAX_SERVE_BATCH} (or null: the number of workers), got {{got}}")] = None
    #: with serve: the longest a request waits for due clients to join its batch
    serve_batch_timeout_ms: Annotated[int | float, rule(
        lambda v: is_number(v) and 0 <= v <= MAX_SERVE_BATCH_TIMEOUT_MS,
        f"{{key}}: expected milliseconds in 0..{MAX_SERVE_BATCH_TIMEOUT_MS}, got {{got}}")] = 50
    #: with serve: auto (shm for executor=local on Linux, else websocket) | shm | websocket
    serve_transport: Annotated[str, rule(lambda v: v in SERVE_TRANSPORTS,
                                         f"{{key}}: expected one of {', '.join(SERVE_TRANSPORTS)}, got {{got}}"),
                               ] = "auto"

    def given(self) -> dict[str, Any]:
        """The keys the config gave, as given (what ``run.json`` stores; defaults left out)."""
        return self.model_dump(exclude_unset=True)


class OpenPolicyOptions(PolicyOptions):
    """The options of a policy whose plugin declares no model: the shared keys checked, its own kept as given."""

    model_config = ConfigDict(extra="allow")


@dataclass(frozen=True)
class PolicyType:
    """A policy plugin's descriptor.

    ``factory(config)`` builds a :class:`Policy` from the run's ``policy`` config group validated by
    :attr:`options`, as a plain dict (every key of the model, defaults filled in). It runs inside each
    worker process, so it must be picklable by name (a module-level function or class).
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
    #: The model of its options (the ``policy`` group), checked before any run directory is made;
    #: the default keeps any key of its own as given.
    options: type[PolicyOptions] = OpenPolicyOptions
