"""The one rollout loop: policy → env → task → recorders, for every executor."""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np

from molmo_lerobot.errors import MolmoError

if TYPE_CHECKING:
    from molmo_lerobot.benchmark_kinds import Session
    from molmo_lerobot.policies.base import Policy
    from molmo_lerobot.recording import Recorder, RecorderGroup
    from molmo_lerobot.results import EpisodeResult


class ActionError(MolmoError, ValueError):
    """A policy returned something that is not a valid action or chunk."""


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


def rollout(session: Session, policy: Policy, recorders: RecorderGroup | list[Recorder],
            policy_name: str) -> EpisodeResult:
    """Play ``session`` (open, its policy reset) with ``policy`` until it ends; its result.

    Chunks run open loop: the policy is asked for a new action (and gets a new observation) when
    the queue is empty. The episode ends after a step whose action says ``done``, with
    ``end_on_success`` after the first successful step, else at the horizon
    (the session's ``end``: every :class:`~molmo_lerobot.benchmark_kinds.Session` keeps its outcome alike). Images are
    rendered only when someone needs them: the policy at the steps where it gets an observation,
    recorders at the steps they ask for (an env suite that draws inside its step is told before
    the step). A recorder that raises fails its output, not the episode (:class:`RecorderGroup`).
    """
    from molmo_lerobot.recording import RecorderGroup

    recs = recorders if isinstance(recorders, RecorderGroup) else RecorderGroup(recorders)
    horizon = session.horizon
    obs = session.observe(policy.needs_images or recs.wants_images_at(0, horizon))
    queue: deque[ChunkStep] = deque()
    while True:
        if not queue:
            queue.extend(split_actions(policy.act(obs), session.move_groups, policy_name))
        planned = queue.popleft()
        said_done = bool(planned.get(DONE_KEY, False))
        action = session.complete({g: a for g, a in planned.items() if isinstance(a, np.ndarray)})
        images = recs.wants_images_at(session.steps + 1, horizon) or (policy.needs_images and not queue)
        success = session.step(action, observed=not queue, images=images)
        ended = session.end(said_done)
        if recs.recorders:
            recs.record_step(obs, action, session.task_reward, success, ended is not None)
        if ended:
            return session.result()
        obs = session.observe(images)
