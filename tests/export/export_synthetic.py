"""Drive LeRobot recorders with synthetic rollouts (no simulator needed)."""

from __future__ import annotations

import numpy as np

from molmo_lerobot.recording import EpisodeInfo
from molmo_lerobot.results import EpisodeIdentity, EpisodeResult, RunSummary, summarize

CAMS = ["exo", "wrist"]
W, H = 32, 24
MOVE_GROUPS = {"arm": 3, "gripper": 1}
JOINTS = {"arm": ["j1", "j2", "j3"], "gripper": ["finger_left", "finger_right"]}


def info(index: int, steps: int, prompt: str = "pick up the mug", expert: bool = False) -> EpisodeInfo:
    return EpisodeInfo(identity=EpisodeIdentity(index, 1000 + index, "pick", prompt, steps, "cli", "",
                                                house_index=index % 3),
                       fps=1000 / 66, camera_names=list(CAMS),
                       img_resolution=(W, H), joint_names=dict(JOINTS), move_groups=dict(MOVE_GROUPS),
                       expert=expert, extra={"robot": "synth_arm"})


def obs(index: int, step: int) -> dict:
    """Images whose brightness encodes (episode, step), so a reader can check which frame it got."""
    level = (index * 37 + step * 5) % 250
    return {
        "images": {c: np.full((H, W, 3), level, np.uint8) for c in CAMS},
        "qpos": {"arm": np.array([index, step, 0.5]), "gripper": np.array([0.01, 0.01])},
        "qvel": {"arm": np.zeros(3), "gripper": np.zeros(2)},
        "prompt": "pick up the mug", "step": step,
    }


def run_episode(rec, index: int, steps: int, success_from: int | None, error: str | None = None,
                reward: bool = False, expert: bool = False, success_until: int | None = None,
                prompt: str = "pick up the mug") -> EpisodeResult:
    """Feed one episode to ``rec``; succeeds from step ``success_from`` on (None: never) up to
    ``success_until`` (None: the end); ``expert``: played by a scripted expert."""
    rec.start_episode(info(index, steps, prompt=prompt, expert=expert))
    ok = once = False
    n = steps if error is None else steps // 2
    for t in range(n):
        ok = success_from is not None and t >= success_from and (success_until is None or t < success_until)
        once |= ok
        action = {"arm": np.array([t, -t, index], float), "gripper": np.array([float(ok)])}
        rec.record_step(obs(index, t), action, float(ok) if reward else None, ok, t == steps - 1)
    if error is not None:
        result = EpisodeResult.failed(index, index % 3, "molmo.tasks.Pick", 1000 + index, error, task_type="pick")
    else:
        result = EpisodeResult(index, index % 3, "molmo.tasks.Pick", ok, once, steps, 1000 + index,
                               task_type="pick", prompt=prompt, horizon=steps)
    rec.end_episode(result)
    return result


def summary_for(results: list[EpisodeResult]) -> RunSummary:
    return summarize(sorted(results, key=lambda r: r.episode_index),
                     benchmark={"name": "synth_v1", "sha256": "ab" * 32, "n_episodes": len(results)},
                     policy={"name": "scripted"}, seed=0)


class NullRecorder:
    """Accepts a rollout and keeps nothing (to compute an episode's result without recording it)."""

    def start_episode(self, info) -> None: ...
    def record_step(self, *args) -> None: ...
    def end_episode(self, result) -> None: ...


def record_then_die(factory, out, worker_id: str, episodes: list[tuple], torn: tuple | None = None) -> None:
    """Child process body: record ``episodes``, then ``torn`` = (index, steps) up to half its steps,
    then die by SIGKILL without closing (the shard of the episode in flight is torn)."""
    import os
    import signal

    rec = factory.make(worker_id, out)
    for args in episodes:
        run_episode(rec, *args)
    if torn is not None:
        index, steps = torn
        rec.start_episode(info(index, steps))
        for t in range(steps // 2):
            rec.record_step(obs(index, t), {"arm": np.zeros(3), "gripper": np.zeros(1)}, None, False, False)
    os.kill(os.getpid(), signal.SIGKILL)
