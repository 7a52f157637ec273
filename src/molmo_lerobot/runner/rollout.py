"""The one rollout loop: policy → env → task → recorders, for every executor."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.features import ENV_STATE_KEY

if TYPE_CHECKING:
    from molmo_lerobot.policies.base import Action, EpisodeContext, Policy
    from molmo_lerobot.recording import EpisodeInfo, Recorder, RecorderGroup


class ActionError(MolmoError, ValueError):
    """A policy returned something that is not a valid action or chunk."""


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


#: the optional action key that ends the episode after its step (MolmoSpaces' ``done``)
DONE_KEY = "done"


#: one step of a policy's output: its action, with ``DONE_KEY: True`` on the step that ends the episode
ChunkStep = dict[str, np.ndarray | bool]


def split_actions(out: Any, move_groups: dict[str, int], policy: str) -> list[ChunkStep]:
    """Validate a policy's output and split it into single-step actions.

    Accepts one action ``{group: (dim,)}`` or a chunk ``{group: (H, dim)}`` (same H for
    every group). A move group may be left out (it holds its position); ``done`` (a bool, or
    one per chunk step; a single bool marks the chunk's last step) ends the episode after
    that step. Raises :class:`ActionError` naming the policy, the group and the problem.
    """
    if not isinstance(out, dict):
        raise ActionError(f"policy {policy!r} returned {type(out).__name__}, expected a dict keyed by move group")
    unknown = sorted(set(out) - set(move_groups) - {DONE_KEY})
    if unknown:
        raise ActionError(f"policy {policy!r} returned unknown move groups {unknown} "
                          f"(the robot has {sorted(move_groups)}; 'done' is the only other key)")
    arrays: dict[str, np.ndarray] = {}
    horizon = None
    for group, dim in move_groups.items():
        if group not in out:
            continue
        try:
            a = np.asarray(out[group], dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ActionError(f"policy {policy!r} returned a non-numeric {group!r} action: {exc}") from None
        if a.ndim == 1 and a.shape[0] == dim:
            a = a[None]
        elif not (a.ndim == 2 and a.shape[1] == dim and a.shape[0] >= 1):
            raise ActionError(
                f"policy {policy!r} returned {group!r} with shape {a.shape}, expected ({dim},) or (H, {dim})"
            )
        if horizon is not None and a.shape[0] != horizon:
            raise ActionError(f"policy {policy!r} returned chunks of different lengths ({horizon} vs {a.shape[0]})")
        horizon = a.shape[0]
        bad = ~np.isfinite(a)
        if bad.any():
            t, j = map(int, np.argwhere(bad)[0])
            raise ActionError(f"policy {policy!r} returned a non-finite value in {group!r} (step {t}, index {j})")
        arrays[group] = a
    if horizon is None and DONE_KEY not in out:
        raise ActionError(f"policy {policy!r} returned no move group (expected some of {sorted(move_groups)})")
    horizon = horizon or 1
    done = np.zeros(horizon, dtype=bool)
    if DONE_KEY in out:
        flag = np.asarray(out[DONE_KEY])
        if flag.dtype.kind not in "bi" or flag.ndim > 1 or (flag.ndim == 1 and flag.shape[0] != horizon):
            raise ActionError(f"policy {policy!r} returned 'done' as {flag.dtype} {flag.shape}: "
                              f"expected a bool or {horizon} bools")
        if flag.ndim == 0:
            done[-1] = bool(flag)
        else:
            done[:] = flag.astype(bool)
    steps: list[ChunkStep] = [{g: a[t] for g, a in arrays.items()} for t in range(horizon)]
    for t in np.flatnonzero(done):
        steps[int(t)][DONE_KEY] = True
    return steps


@dataclass
class RolloutOutcome:
    """``success_once`` is sampled where MolmoSpaces samples it (after each action chunk and at
    the episode's end); ``success_any_step`` after every policy step (finer, an extra)."""

    success: bool
    success_once: bool
    steps: int
    success_any_step: bool = False
    ended_by: str = "horizon"  # "horizon" | "success" (end_on_success) | "done" (the policy said so)


def advance(env: Any, task: Any, action: Action, when: str) -> bool:
    """One policy step of ``env`` towards a complete ``action``; divergence is an error naming
    ``when``. Returns the task's success in the new state. The rollout and the Gymnasium env both
    step episodes here."""
    env.step(action)
    data = getattr(env, "data", None)
    if data is not None:
        check_divergence(data, when)
    return bool(task.success())


def rollout(env: Any, task: Any, policy: Policy, ctx: EpisodeContext, horizon: int,
            recorders: RecorderGroup | list[Recorder], info: EpisodeInfo, policy_name: str,
            end_on_success: bool = False, environment_state: bool = False) -> RolloutOutcome:
    """Run one episode for up to ``horizon`` policy steps; report success at the end and at any step.

    A move group the policy leaves out holds its current target. The episode ends early
    after a step whose action says ``done``, or, with ``end_on_success``, after the first
    successful step. Images are rendered only when someone needs them: the policy at the
    steps where it is asked for a new action (chunks run open loop), recorders at the steps
    they ask for. A recorder that raises fails its output, not the episode (:class:`RecorderGroup`).
    With ``environment_state`` every observation carries the task's (``Task.environment_state``).
    """
    from molmo_lerobot.recording import RecorderGroup

    recs = recorders if isinstance(recorders, RecorderGroup) else RecorderGroup(recorders)
    policy.reset(ctx)
    task.setup()
    data = getattr(env, "data", None)
    if data is not None:
        check_divergence(data, "at the initial state")
    recs.start_episode(info)

    def record_images(step: int) -> bool:
        return recs.wants_images_at(step, horizon)

    def observe(step: int, images: bool) -> dict[str, Any]:
        obs = env.observe(images=images)
        obs["prompt"], obs["step"] = ctx.prompt, step
        if environment_state:
            obs[ENV_STATE_KEY] = task.environment_state()
        return obs

    obs = observe(0, policy.needs_images or record_images(0))
    queue: deque[ChunkStep] = deque()
    success = success_once = any_step = False
    ended_by, steps = "horizon", horizon
    for step in range(horizon):
        if not queue:
            queue.extend(split_actions(policy.act(obs), env.move_groups, policy_name))
        planned = queue.popleft()
        said_done = bool(planned.get(DONE_KEY, False))
        action: Action = {g: a for g, a in planned.items() if isinstance(a, np.ndarray)}
        for group in env.move_groups:  # a left-out group holds its target
            if group not in action:
                action[group] = env.robot.targets(env.data, group)
        success = advance(env, task, action, f"at step {step}")
        any_step |= success
        if said_done:
            ended_by = "done"
        elif end_on_success and success:
            ended_by = "success"
        done = step == horizon - 1 or ended_by != "horizon"
        if not queue or done:  # an observation instant: MolmoSpaces samples success here
            success_once |= success
        if recs.recorders:
            recs.record_step(obs, action, task.reward(), success, done)
        if done:
            steps = step + 1
            break
        obs = observe(step + 1, record_images(step + 1) or (policy.needs_images and not queue))
    return RolloutOutcome(success=success, success_once=success_once, steps=steps, success_any_step=any_step,
                          ended_by=ended_by)


def resolve_horizon(override: int | None, task_spec: Any, default_sec: float, policy_dt_ms: float,
                    task_sec: float | None = None) -> int:
    """Policy steps: CLI override (steps), else the run's per-task horizon (``task_sec``), else
    the episode's ``task_horizon_sec``, else the task type's default."""
    return horizon_with_source(override, task_spec, default_sec, policy_dt_ms, task_sec)[0]


def horizon_with_source(override: int | None, task_spec: Any, default_sec: float | None, policy_dt_ms: float,
                        task_sec: float | None = None) -> tuple[int, str]:
    """:func:`resolve_horizon` and where it came from: ``cli``, ``task_horizons``,
    ``task_horizon_sec`` or ``default``."""
    if override is not None:
        return int(override), "cli"
    episode_sec = getattr(task_spec, "task_horizon_sec", None)
    seconds, source = ((task_sec, "task_horizons") if task_sec else
                       (episode_sec, "task_horizon_sec") if episode_sec else (default_sec, "default"))
    if seconds is None:
        raise ValueError("no horizon: set horizon=, horizons.<task type> or the episode's task_horizon_sec")
    return max(1, round(float(seconds) * 1000.0 / policy_dt_ms)), source
