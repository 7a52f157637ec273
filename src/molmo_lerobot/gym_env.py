"""Our benchmarks as Gymnasium environments, in LeRobot's env convention.

``gymnasium.make("molmo_lerobot/<benchmark>")`` works for every shipped benchmark once this
module is imported, which loads no plugin; :func:`register_benchmarks` adds the ids of the benchmarks
plugins ship (``molmo_lerobot/Benchmark`` takes ``benchmark=<name or directory>`` without it).
The env steps the very ``Env`` and ``Task`` objects that ``molmo-eval``'s rollout steps; it
adds no physics or success logic of its own. The env-suite benchmarks (``libero_*``, ``pusht``) have no id here:
they are LeRobot's own envs (``--env.type=libero|pusht``), which ``molmo-eval`` plays and is proven equal to.

Episodes and seeds
    ``reset(seed=s)`` runs benchmark episode ``s mod N``; ``reset()`` without a seed runs the
    next episode in benchmark order (starting at 0); ``episode_index=k`` pins one episode.
    The simulator seed of episode ``i`` is ``molmo-eval``'s (derived from ``run_seed`` and the
    episode's content), so episode ``i`` here and episode ``i`` of ``molmo-eval seed=<run_seed>``
    are the same trial. ``lerobot-eval --seed=S`` seeds its ``b``-th env of batch ``k`` with
    ``S + k * batch_size + b``: with ``--seed=0`` its episode order is benchmark order.

Observation
    ``{"pixels": {camera: uint8 (H, W, 3)}, "agent_pos": float32 (n,)}``: ``agent_pos`` is the
    ``observation.state`` of our recorded datasets (each move group's joint positions, in the
    robot's move-group order; the gripper as 0 open … 1 closed), both from one feature map
    (:mod:`molmo_lerobot.features`, the env's ``features``). With ``environment_state=True`` it
    also has ``environment_state``: the task's privileged ground truth, the recorded
    ``observation.environment_state`` (e.g. pick: the object's pose in the robot base frame, its
    size, the TCP-to-object vector).

Action
    float32 ``(n,)``: the robot's move groups concatenated in that same order (the
    ``action`` feature of our datasets), e.g. Franka: 7 arm joint targets + 1 gripper command.
    Every value is an absolute position target, so ``action_space`` is bounded by what the robot
    clips targets to: each arm joint's range (its actuator's ctrl range), the gripper's 0 open … 1
    closed, a mobile base's x and y (m, from its start) by its actuators' range and its yaw as a
    heading in [-π, π]; ``action_space.sample()`` is a reachable pose.

The reward is the task's own (``Task.reward``: e.g. the opening fraction for open/close), else
1.0 on success and 0.0 otherwise. ``info`` carries ``is_success`` (success in the current state, LeRobot's key),
``success_once``, ``episode_index``, ``task`` (the task type), ``task_description`` (the prompt), ``seed`` and
``horizon``. ``terminated`` is set on success when ``end_on_success``; ``truncated`` at the horizon.
``render()`` returns the first exterior (non-wrist) camera's image.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from molmo_lerobot.gl import use_headless_gl

use_headless_gl()  # before MuJoCo is imported (by the imports below): unset, it would pick GLFW and need a display

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from gymnasium import spaces  # noqa: E402

from molmo_lerobot.benchmark.packs import benchmark_pack  # noqa: E402
from molmo_lerobot.context import RunContext  # noqa: E402
from molmo_lerobot.errors import MolmoError  # noqa: E402
from molmo_lerobot.features import ENV_STATE_KEY, FeatureMap, is_wrist  # noqa: E402
from molmo_lerobot.molmospaces.preflight import preflight  # noqa: E402
from molmo_lerobot.paths import data_path  # noqa: E402
from molmo_lerobot.runner.episode import EpisodeSession, EpisodeSetupError, load_run_benchmark  # noqa: E402
from molmo_lerobot.runner.plan import EpisodePlanner  # noqa: E402

if TYPE_CHECKING:
    from molmo_lerobot.plugins import Plugins

NAMESPACE = "molmo_lerobot"


class EpisodeIndexError(MolmoError, IndexError):
    """An episode index outside the benchmark."""


class MolmoEnv(gym.Env):
    """One benchmark as a Gymnasium env; see the module docstring for the conventions."""

    # gymnasium reads it from the class (render modes) and types it as an instance attribute
    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 15}  # noqa: RUF012

    def __init__(self, benchmark: str = "pick_v1", *, episode_index: int | None = None, run_seed: int = 0,
                 horizon: int | None = None, end_on_success: bool = False, timing: dict[str, float] | None = None,
                 eval_options: dict[str, Any] | None = None, render_mode: str | None = "rgb_array",
                 environment_state: bool = False) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        self.render_mode = render_mode
        #: this env's run: molmo-eval's options (``eval_options``), seed, horizon and timing, validated as
        #: molmo-eval validates its config (:class:`~molmo_lerobot.run_config.RunConfigError` names each problem)
        self.run = RunContext.build({**(eval_options or {}), "seed": run_seed, "horizon": horizon,
                                     "timing": timing or {}})
        self.bench = load_run_benchmark(_not_a_suite(benchmark, self.run.plugins), self.run.plugins)
        self.run = self.run.for_benchmark(self.bench)  # the look its metadata names
        self.end_on_success = bool(end_on_success)
        self.environment_state = bool(environment_state)
        self._n = len(self.bench.episodes)
        self._pinned = None if episode_index is None else self._check_index(episode_index)
        planner = EpisodePlanner(self.run, self.bench)
        self._plans = [planner.plan(i) for i in range(self._n)]  # episode i is the same trial on every reset
        self._next = 0
        self.metadata = {**self.metadata, "render_fps": round(1000.0 / self.run.timing.policy_dt_ms)}
        #: the longest horizon of the benchmark (LeRobot's rollout loop bound)
        self._max_episode_steps = max(plan.horizon or 0 for plan in self._plans)
        self._episode: EpisodeSession | None = self._open(self._pinned or 0)  # spaces come from a real episode
        self.observation_space, self.action_space = self._spaces()

    # Gymnasium API --------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if self._pinned is not None:
            index = self._pinned
        elif seed is not None:
            index = int(seed) % self._n
        else:
            index = self._next
        self._next = (index + 1) % self._n
        self._close_episode()
        self._episode = self._open(index)  # compiled models are cached: reopening is cheap
        obs = self._episode.observe()
        self._check_layout(obs)
        return self._obs(obs), self._info(False)

    def step(self, action: np.ndarray):
        if self._episode is None:
            raise RuntimeError("step() before reset()")
        ep = self._episode
        a = np.asarray(action, dtype=np.float64).reshape(-1) if not isinstance(action, dict) else action
        if isinstance(a, np.ndarray) and a.shape != (self.features.action_dim,):
            raise ValueError(f"action has shape {np.shape(action)}, expected ({self.features.action_dim},): "
                             f"{self.features.action_layout()}")
        success = ep.step(self.features.split_action(a) if isinstance(a, np.ndarray) else a)
        ended = ep.end()
        return self._obs(ep.observe()), ep.reward, ended == "success", ended == "horizon", self._info(success)

    def render(self) -> np.ndarray | None:
        if self.render_mode is None or self._episode is None:
            return None
        cams = self._episode.env.camera_names
        exterior = next((c for c in cams if not is_wrist(c)), cams[0])
        return self._episode.env.render(exterior)

    def close(self) -> None:
        self._close_episode()

    # LeRobot's vector env calls these by name ---------------------------------------------------------
    def task_description(self) -> str:
        return self._episode.plan.prompt if self._episode else ""

    def task(self) -> str:
        return self._episode.plan.task_type if self._episode else ""

    # Internals --------------------------------------------------------------------------------
    def _open(self, index: int) -> EpisodeSession:
        """Episode ``index``, checked to simulate here, open (as a ``molmo-eval`` worker opens it)."""
        plan = self._plans[index]
        if plan.error:
            raise EpisodeSetupError(f"{self.bench.where(index)}: {plan.error}")
        cannot = preflight(self.bench, self.run, [index])
        if cannot:
            raise EpisodeSetupError(cannot)
        return EpisodeSession.open(plan, self.run, end_on_success=self.end_on_success,
                                   environment_state="environment_state=True" if self.environment_state else None)

    @property
    def _current(self) -> EpisodeSession:
        """The open episode (a closed env has none)."""
        if self._episode is None:
            raise RuntimeError("the env is closed; reset() opens an episode")
        return self._episode

    def _check_index(self, index: int) -> int:
        if isinstance(index, bool) or not isinstance(index, int | np.integer) or not 0 <= index < self._n:
            raise EpisodeIndexError(f"episode_index {index!r} is outside benchmark {self.bench.name!r} "
                                    f"({self._n} episodes: 0..{self._n - 1})")
        return int(index)

    def _spaces(self) -> tuple[spaces.Dict, spaces.Box]:
        #: the feature map of this env's episodes: ``agent_pos`` is its ``observation.state``, the action its ``action``
        self.features = self._feature_map(self._current.observe())
        cams = self.features.camera_shapes
        pixels = spaces.Dict({c: spaces.Box(0, 255, shape, np.uint8) for c, shape in cams.items()})
        obs_space = spaces.Dict({"pixels": pixels,
                                 "agent_pos": spaces.Box(-np.inf, np.inf, (self.features.state_dim,), np.float32)})
        if self.features.env_state_names:
            obs_space[ENV_STATE_KEY] = spaces.Box(-np.inf, np.inf, (len(self.features.env_state_names),), np.float32)
        lo, hi = self._action_bounds()
        return obs_space, spaces.Box(lo, hi, dtype=np.float32)

    def _action_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Each move group's target bounds, in the action's order: what the robot clips a target to
        (joint and actuator ranges; the gripper 0 … 1; a base's heading ±π), unbounded where it does not say."""
        robot, lo, hi = self._current.env.robot, [], []
        for group, dim in self.features.move_groups.items():
            bounds = robot.command_range(group)
            lo.append(np.full(dim, -np.inf) if bounds is None else bounds[0])
            hi.append(np.full(dim, np.inf) if bounds is None else bounds[1])
        return np.concatenate(lo).astype(np.float32), np.concatenate(hi).astype(np.float32)

    def _feature_map(self, obs: dict[str, Any]) -> FeatureMap:
        ep = self._current
        return FeatureMap.from_observation(ep.env.move_groups, ep.env.joint_names, ep.env.camera_names, obs,
                                           ep.task.environment_state_names)

    def _check_layout(self, obs: dict[str, Any]) -> None:
        """Every episode of one env must share the spaces (cameras, resolution, move groups)."""
        new, ours = self._feature_map(obs), self.features
        if (new.camera_shapes != ours.camera_shapes or new.move_groups != ours.move_groups
                or new.env_state_names != ours.env_state_names):
            where = self.bench.where(self._current.plan.episode_index)
            raise ValueError(f"{where}: cameras {new.camera_shapes} / move groups {new.move_groups} differ from "
                             f"this env's spaces ({ours.camera_shapes} / {ours.move_groups}); "
                             "pin episode_index to run it")

    def _obs(self, obs: dict[str, Any]) -> dict[str, Any]:
        out = {"pixels": {c: np.asarray(obs["images"][c], dtype=np.uint8) for c in self.features.camera_shapes},
               "agent_pos": self.features.state_vector(obs["qpos"])}
        if self.features.env_state_names:
            out[ENV_STATE_KEY] = self.features.env_state_vector(obs)
        return out

    def _info(self, success: bool) -> dict[str, Any]:
        plan = self._current.plan
        return {"is_success": bool(success), "success_once": self._current.success_once,
                "episode_index": plan.episode_index, "task": plan.task_type, "task_description": plan.prompt,
                "seed": plan.seed, "horizon": plan.horizon}

    def _close_episode(self) -> None:
        if self._episode is not None:
            self._episode.close()
            self._episode = None


def _not_a_suite(benchmark: str, plugins: Plugins) -> str:
    """``benchmark``, unless another benchmark kind than episode files claims it (an env suite's: LeRobot's own
    Gymnasium envs already, ``lerobot-eval --env.type=libero|pusht``, the envs molmo-eval is proven equal to), so
    this package registers no id for them and says so in one line."""
    from pathlib import Path

    from molmo_lerobot.benchmark_kinds import benchmark_kind

    kind = None if Path(str(benchmark)).exists() else benchmark_kind(plugins, str(benchmark))
    if kind is not None and kind.name != "episodes":
        raise EpisodeSetupError(
            f"benchmark {benchmark!r} is of benchmark kind {kind.name!r} ({kind.description}): it runs in molmo-eval "
            f"(benchmark={benchmark}) but is not a Gymnasium env of this package; as a Gymnasium env use its "
            f"own (an env suite's: lerobot-eval --env.type={kind.name})")
    return benchmark


#: what ``gym.make`` imports (a string: gymnasium's entry point type takes no class)
ENTRY_POINT = f"{__name__}:MolmoEnv"


def register_benchmarks(namespace: str = NAMESPACE, plugins: Plugins | None = None) -> list[str]:
    """Register ``<namespace>/<name>`` for every benchmark the plugins register (``plugins``; None: the
    installed ones, loaded now) and ``<namespace>/Benchmark``; the ids registered."""
    from molmo_lerobot.benchmark.registry import benchmark_names
    from molmo_lerobot.plugins import Plugins

    return _register(namespace, benchmark_names(plugins or Plugins()))


def _register(namespace: str, names: list[str]) -> list[str]:
    ids = []
    for name in names:
        env_id = f"{namespace}/{name}"
        if env_id not in gym.registry:
            gym.register(env_id, entry_point=ENTRY_POINT, kwargs={"benchmark": name}, disable_env_checker=True)
        ids.append(env_id)
    generic = f"{namespace}/Benchmark"
    if generic not in gym.registry:
        gym.register(generic, entry_point=ENTRY_POINT, disable_env_checker=True)
    return [*ids, generic]


# The benchmarks this package ships (the core plugin's), found without loading any plugin;
# a plugin's benchmarks get their ids from register_benchmarks().
_register(NAMESPACE, [b.name for b in benchmark_pack(data_path("benchmarks"))])
