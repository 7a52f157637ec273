"""The one rollout loop: policy → env → task → recorders, for every executor."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from molmo_lerobot.policies.base import Action, EpisodeContext, Policy
    from molmo_lerobot.runner.recorders import EpisodeInfo, Recorder


class ActionError(ValueError):
    """A policy returned something that is not a valid action or chunk."""


def split_actions(out: Any, move_groups: dict[str, int], policy: str) -> list[Action]:
    """Validate a policy's output and split it into single-step actions.

    Accepts one action ``{group: (dim,)}`` or a chunk ``{group: (H, dim)}`` (same H for
    every group). Raises :class:`ActionError` naming the policy, the group and the problem.
    """
    if not isinstance(out, dict):
        raise ActionError(f"policy {policy!r} returned {type(out).__name__}, expected a dict keyed by move group")
    missing = sorted(set(move_groups) - set(out))
    unknown = sorted(set(out) - set(move_groups))
    if missing or unknown:
        raise ActionError(
            f"policy {policy!r} returned move groups {sorted(out)}, expected {sorted(move_groups)}"
            + (f" (missing {missing})" if missing else "") + (f" (unknown {unknown})" if unknown else "")
        )
    arrays: dict[str, np.ndarray] = {}
    horizon = None
    for group, dim in move_groups.items():
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
    assert horizon is not None
    return [{g: a[t] for g, a in arrays.items()} for t in range(horizon)]


@dataclass
class RolloutOutcome:
    success: bool
    success_once: bool
    steps: int


def rollout(env: Any, task: Any, policy: Policy, ctx: EpisodeContext, horizon: int,
            recorders: list[Recorder], info: EpisodeInfo, policy_name: str) -> RolloutOutcome:
    """Run one episode for ``horizon`` policy steps and report success at the end and at any step.

    Images are rendered only when someone needs them: the policy at the steps where it is
    asked for a new action (chunks run open loop), recorders at the steps they ask for.
    """
    policy.reset(ctx)
    task.setup()
    for rec in recorders:
        rec.start_episode(info)
    def record_images(step: int) -> bool:
        return any(r.wants_images_at(step, horizon) for r in recorders)

    obs = env.observe(images=policy.needs_images or record_images(0))
    obs["prompt"], obs["step"] = ctx.prompt, 0
    queue: deque[Action] = deque()
    success = success_once = False
    for step in range(horizon):
        if not queue:
            queue.extend(split_actions(policy.act(obs), env.move_groups, policy_name))
        action = queue.popleft()
        env.step(action)
        success = bool(task.success())
        success_once |= success
        done = step == horizon - 1
        if recorders:
            reward = task.reward()
            for rec in recorders:
                rec.record_step(obs, action, reward, success, done)
        if not done:
            obs = env.observe(images=record_images(step + 1) or (policy.needs_images and not queue))
            obs["prompt"], obs["step"] = ctx.prompt, step + 1
    return RolloutOutcome(success=success, success_once=success_once, steps=horizon)


def resolve_horizon(override: int | None, task_spec: Any, default_sec: float, policy_dt_ms: float,
                    task_sec: float | None = None) -> int:
    """Policy steps: CLI override (steps), else the run's per-task horizon (``task_sec``), else
    the episode's ``task_horizon_sec``, else the task type's default."""
    if override is not None:
        return int(override)
    seconds = task_sec or getattr(task_spec, "task_horizon_sec", None) or default_sec
    return max(1, int(round(float(seconds) * 1000.0 / policy_dt_ms)))
