"""The episode session: one planned episode, live, the same wherever it runs.

``molmo-eval``'s workers (:func:`~molmo_lerobot.runner.rollout.rollout`), the Gymnasium env
(and through it LeRobot's ``--env.type=molmo``) and ``policy=remote`` all run an episode as an
:class:`EpisodeSession`, so episode ``i`` with run seed ``s`` is the same trial everywhere:

* :meth:`EpisodeSession.open`: plan → scene (built, reset with the plan's seed) → task (set up,
  the start checked for divergence and, when asked, for an environment state) → policy reset;
* :meth:`~EpisodeSession.observe` and :meth:`~EpisodeSession.step` (one policy step), which also
  keep the episode's outcome: ``success`` (the last state), ``success_once`` (at the instants
  the agent observes: after each action chunk, every step in the Gymnasium env, and at the end),
  ``success_any_step`` (after every step) and what ended it (:meth:`~EpisodeSession.end`);
* :meth:`~EpisodeSession.close` and :meth:`~EpisodeSession.result`, the
  :class:`~molmo_lerobot.results.EpisodeResult`.

Its identity (index, seed, digest, task type, prompt, horizon) is its plan's frozen
:class:`~molmo_lerobot.results.EpisodeIdentity`, which the recorders'
:class:`~molmo_lerobot.recording.EpisodeInfo` embeds; the policy's
:class:`~molmo_lerobot.policies.base.EpisodeContext` and the result are made from it here, once.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from molmo_lerobot.errors import InfrastructureError, MolmoError, describe
from molmo_lerobot.features import ENV_STATE_KEY
from molmo_lerobot.results import EpisodeOutcome

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.load import Benchmark
    from molmo_lerobot.benchmark.schema import EpisodeSpec
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.episode_plan import EpisodePlan
    from molmo_lerobot.plugins import Plugins
    from molmo_lerobot.policies.base import Action, EpisodeContext, Observation, Policy
    from molmo_lerobot.recording import EpisodeInfo
    from molmo_lerobot.results import EpisodeResult
    from molmo_lerobot.sim.env import Env
    from molmo_lerobot.tasks.base import Task


class SimulationDiverged(MolmoError, RuntimeError):
    """The physics blew up (non-finite state or a MuJoCo instability warning): the episode is an error."""


#: MuJoCo warnings that mean the simulation state can no longer be trusted (MuJoCo resets
#: the state after a bad acceleration, so a blow-up can look like a calm, failed episode).
DIVERGENCE_WARNINGS = {name: int(getattr(mujoco.mjtWarning, name))
                       for name in ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC", "mjWARN_BADCTRL")}


def check_divergence(data: Any, when: str) -> None:
    """Raise :class:`SimulationDiverged` if ``data`` (an ``MjData``) holds non-finite state or
    has raised one of :data:`DIVERGENCE_WARNINGS` since it was reset; ``when`` locates it."""
    for name, index in DIVERGENCE_WARNINGS.items():
        info = data.warning[index]
        if info.number > 0:
            raise SimulationDiverged(f"simulation diverged {when} (t={data.time:.3f}s): MuJoCo {name} "
                                     f"x{info.number} (dof/index {info.lastinfo}); check init_qpos and object poses")
    for field in ("qpos", "qvel", "qacc"):
        values = getattr(data, field)
        if not np.all(np.isfinite(values)):
            bad = int(np.flatnonzero(~np.isfinite(values))[0])
            raise SimulationDiverged(f"simulation diverged {when} (t={data.time:.3f}s): non-finite {field}[{bad}]")


class EpisodeSetupError(MolmoError, ValueError):
    """An episode that cannot be set up; the message names the file, episode and field."""


def load_run_benchmark(benchmark: str | Path, plugins: Plugins) -> Benchmark:
    """A benchmark by directory/file path or registered name; one clear error otherwise."""
    from molmo_lerobot.benchmark.load import load_benchmark
    from molmo_lerobot.benchmark.registry import UnknownBenchmark, find_benchmark

    try:
        return load_benchmark(find_benchmark(benchmark, plugins), plugins)
    except UnknownBenchmark as exc:
        raise EpisodeSetupError(str(exc)) from None


def install_failure(exc: Exception, spec: EpisodeSpec, run: RunContext) -> Exception:
    """``exc``, raised building ``spec``'s scene, as an :class:`InfrastructureError` when the scene
    dataset's installed files are broken now (``resume=true`` reruns the episode once they are
    repaired), else ``exc`` itself."""
    try:
        problem = run.plugins.scene_dataset(spec.scene_dataset).install_problem()
    except Exception:
        return exc
    if problem is None:
        return exc
    return InfrastructureError(f"{problem} (the scene failed to build: {describe(exc)})")


class EpisodeSession(EpisodeOutcome):
    """One planned episode, open: its env and task, its outcome so far. See the module docstring."""

    def __init__(self, plan: EpisodePlan, spec: EpisodeSpec, env: Env, task: Task, run: RunContext, *,
                 environment_state: bool = False, end_on_success: bool = False) -> None:
        self.plan, self.spec, self.env, self.task, self.run = plan, spec, env, task, run
        #: observations carry the task's environment state (``observation.environment_state``)
        self.environment_state = environment_state
        self.end_on_success = end_on_success
        super().__init__()

    @classmethod
    def open(cls, plan: EpisodePlan, run: RunContext, *, policy: Policy | None = None,
             environment_state: str | None = None, end_on_success: bool = False) -> EpisodeSession:
        """``plan`` under ``run``: its scene built and reset with the plan's seed, its task made, then
        :meth:`start`. Closes what it built if any of it fails."""
        from molmo_lerobot.runner.episode_env import build_env

        spec = plan.episode(run.plugins)
        task_type = run.plugins.task_type(plan.task_type)
        try:
            env = build_env(spec, run.timing_for(spec.scene_dataset), run, run.config.camera.model_dump())
        except Exception as exc:
            raise install_failure(exc, spec, run) from exc
        try:
            env.reset(plan.seed)
            return cls.start(plan, spec, env, task_type.create(spec, env), run, policy=policy,
                             environment_state=environment_state, end_on_success=end_on_success)
        except BaseException:
            env.close()
            raise

    @classmethod
    def start(cls, plan: EpisodePlan, spec: EpisodeSpec, env: Env, task: Task, run: RunContext, *,
              policy: Policy | None = None, environment_state: str | None = None,
              end_on_success: bool = False) -> EpisodeSession:
        """The episode of a reset ``env`` and its ``task``: the task set up, the start checked (divergence;
        an environment state when ``environment_state`` names who asks for one), then ``policy`` reset.
        :meth:`open` starts every planned episode here; a test may start one it built itself."""
        task.setup()
        check_divergence(env.data, "at the initial state")
        if environment_state and not task.environment_state_names:
            raise ValueError(f"task type {plan.task_type!r} defines no environment state "
                             f"(asked for by {environment_state})")
        session = cls(plan, spec, env, task, run, environment_state=bool(environment_state),
                      end_on_success=end_on_success)
        if policy is not None:
            policy.reset(session.policy_context(privileged=policy.needs_simulator))
        return session

    @property
    def horizon(self) -> int:
        return int(self.plan.horizon or 0)

    def policy_context(self, privileged: bool = False) -> EpisodeContext:
        """What the policy learns at reset; ``privileged``: the simulator, the asset catalog and the
        expert of the episode's task type too (scripted experts)."""
        from molmo_lerobot.policies.base import EpisodeContext

        expert = None
        if privileged:
            with contextlib.suppress(LookupError):  # none: the policy says whether it needs one
                expert = self.run.plugins.expert(self.plan.task_type)
        return EpisodeContext.of_plan(self.plan, self.env.move_groups, self.env.timing.policy_dt_s, spec=self.spec,
                                      env=self.env if privileged else None,
                                      catalog=self.run.catalog if privileged else None, expert=expert)

    @property
    def move_groups(self) -> dict[str, int]:
        return dict(self.env.move_groups)

    @property
    def renderer_setup_s(self) -> float:
        return self.env.renderer_setup_s

    def recorder_info(self, *, expert: bool, extra: dict[str, Any]) -> EpisodeInfo:
        """What a recorder learns when the episode starts (``extra``: the run's, e.g. policy and benchmark)."""
        from molmo_lerobot.recording import EpisodeInfo

        plan, env = self.plan, self.env
        return EpisodeInfo(
            identity=plan.identity, fps=1000.0 / env.timing.policy_dt_ms, camera_names=list(env.camera_names),
            img_resolution=(int(self.spec.img_resolution[0]), int(self.spec.img_resolution[1])),
            joint_names=dict(env.joint_names), move_groups=dict(env.move_groups), expert=expert,
            extra={"task_cls": plan.task_cls, "robot": self.spec.robot.robot_name,
                   "object": getattr(self.spec.task, "pickup_obj_name", None), **extra},
            catalog=self.run.catalog,
            environment_state_names=tuple(self.task.environment_state_names) if self.environment_state else (),
        )

    def observe(self, images: bool = True) -> Observation:
        """The observation now: the env's, with the prompt, the step and (if asked) the environment state."""
        obs = self.env.observe(images=images)
        obs["prompt"], obs["step"] = self.plan.prompt, self.steps
        if self.environment_state:
            obs[ENV_STATE_KEY] = self.task.environment_state()
        return obs

    def complete(self, action: Action) -> Action:
        """``action`` with every move group it leaves out holding its current target."""
        held = {g: self.env.robot.targets(self.env.data, g) for g in self.env.move_groups if g not in action}
        return {**action, **held} if held else action

    def step(self, action: Action, *, observed: bool = True, images: bool = True) -> bool:
        """One policy step towards ``action`` (:meth:`complete`); divergence is an error. ``observed``:
        the agent observes the new state (a chunk's last step; every Gymnasium step), so it counts
        for ``success_once``. ``images`` (whether the next :meth:`observe` asks for them) changes nothing
        here: this env draws in :meth:`observe`. Returns success in the new state; the step's reward is the
        task's own (``Task.reward``), else 1.0 on success and 0.0 otherwise (the Gymnasium env's)."""
        self.env.step(self.complete(action))
        check_divergence(self.env.data, f"at step {self.steps}")
        return self.count_step(bool(self.task.success()), observed, self.task.reward())

    def result(self) -> EpisodeResult:
        """The episode's outcome as a result (``duration_s`` and outputs are the worker's)."""
        from molmo_lerobot.results import EpisodeResult

        plan = self.plan
        odd = tuple(self.task.start_warnings)
        notes = self.task.parity_notes()  # judged now, in the final state
        return EpisodeResult(
            episode_index=plan.episode_index, house_index=plan.house_index, task_cls=plan.task_cls,
            success=self.success, success_once=self.success_once, steps=self.steps, seed=plan.seed,
            task_type=self.plan.task_type, prompt=plan.prompt, horizon=self.horizon,
            extra={"ended_by": self.ended_by or "horizon", "end_on_success": self.end_on_success,
                   "success_any_step": self.success_any_step, "camera_system": self.env.camera_system,
                   **self.rewards(),
                   **({"start_warnings": list(odd)} if odd else {}),
                   **({"parity_notes": list(notes)} if notes else {})},
        )

    def close(self) -> None:
        self.env.close()
