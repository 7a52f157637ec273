"""``eval_info.json``: a run's score in the schema ``lerobot-eval`` (LeRobot 0.6.x) writes, beside ``results.json``.

``lerobot-eval`` writes what its ``eval_policy_all`` returns: ``per_task``, one row per task (``task_group``,
``task_id``, ``metrics``: the task's per-episode ``sum_rewards``, ``max_rewards`` and ``successes`` in episode
order, and ``video_paths``, ``predicted_video_paths``), ``per_group`` (``avg_sum_reward``, ``avg_max_reward``,
``pc_success``, ``n_episodes`` and the video paths per task group) and ``overall`` (the same over every episode,
with ``eval_s`` and ``eval_ep_s``). Here, with its meanings:

* a task's group is the benchmark (``libero_object``, ``pusht``: the suite ``lerobot-eval`` names; ours:
  ``pick_v1`` …) and its id LIBERO's task id, else the task's place in ``results.json``'s ``per_task`` order
  (PushT's one task: 0); each row also names its ``per_task`` key (``task``);
* an episode's ``sum_rewards`` / ``max_rewards`` entry is the sum and maximum of its steps' rewards up to the
  step that ended it (the env's; for our benchmarks the Gymnasium env's: the task's own reward, else 1.0 on
  success), as ``lerobot-eval`` masks the steps after an episode's first ``done`` (with ``--eval.batch_size``
  > 1 its mask keeps one step more, a finished env's zeroed reward); its ``successes`` entry whether any step
  succeeded (``lerobot-eval``'s rule; ``extra.success_any_step`` of ``episodes.jsonl``);
* an episode that errored is a failure (as in ``results.json``) whose rewards are ``null``; the averages
  skip ``null`` (``lerobot-eval``'s ``nanmean``), and an average over no episode is ``null`` (theirs: NaN);
* ``eval_s`` is the run's ``wall_time_s`` (a resumed run's: its last session's); no video is written, so
  the video paths are empty.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.results import EpisodeResult, RunSummary

EVAL_INFO_FILE = "eval_info.json"


def _no_videos() -> dict[str, list[str]]:
    return {"video_paths": [], "predicted_video_paths": []}


def _task(r: EpisodeResult) -> str:
    return r.task_type or r.task_cls or "unknown"  # as summarize groups per_task


def _episode(r: EpisodeResult) -> tuple[float | None, float | None, bool]:
    """(sum_reward, max_reward, success) of one episode as ``lerobot-eval`` counts them."""
    if r.error is not None:
        return None, None, False
    success = bool(r.extra.get("success_any_step", r.success_once or r.success))  # older records: at chunk ends
    return r.extra.get("sum_reward"), r.extra.get("max_reward"), success


def _mean(values: list[float | None]) -> float | None:
    kept = [float(v) for v in values if v is not None]
    return sum(kept) / len(kept) if kept else None


def _aggregate(metrics: dict[str, list[Any]]) -> dict[str, Any]:
    successes = metrics["successes"]
    return {"avg_sum_reward": _mean(metrics["sum_rewards"]), "avg_max_reward": _mean(metrics["max_rewards"]),
            "pc_success": 100.0 * sum(successes) / len(successes) if successes else None,
            "n_episodes": len(metrics["sum_rewards"])}


def eval_info(summary: RunSummary, results: list[EpisodeResult]) -> dict[str, Any]:
    """The run's ``eval_info.json`` document (see the module docstring)."""
    group = summary.benchmark.name if summary.benchmark else "unknown"
    order = {task: i for i, task in enumerate(summary.per_task)}
    by_task: dict[str, list[EpisodeResult]] = defaultdict(list)
    for r in sorted(results, key=lambda r: r.episode_index):
        by_task[_task(r)].append(r)
    rows = []
    for task, rs in by_task.items():
        task_id = rs[0].extra.get("task_id", order.get(task, len(order)))
        sums, maxes, successes = (list(column) for column in zip(*map(_episode, rs), strict=True))
        metrics = {"sum_rewards": sums, "max_rewards": maxes, "successes": successes, **_no_videos()}
        rows.append({"task_group": group, "task_id": task_id, "task": task, "metrics": metrics})
    rows.sort(key=lambda row: (row["task_id"], row["task"]))
    every = {key: [v for row in rows for v in row["metrics"][key]]
             for key in ("sum_rewards", "max_rewards", "successes")}
    n = len(every["successes"])
    eval_s = float(summary.wall_time_s or 0.0)
    return {"per_task": rows, "per_group": {group: {**_aggregate(every), **_no_videos()}} if rows else {},
            "overall": {**_aggregate(every), "eval_s": eval_s, "eval_ep_s": eval_s / max(1, n), **_no_videos()}}


def write_eval_info(output_dir: Path, summary: RunSummary, results: list[EpisodeResult]) -> Path:
    """Write ``output_dir/eval_info.json`` (atomically) and return its path."""
    path = Path(output_dir) / EVAL_INFO_FILE
    return atomic_write(path, json.dumps(eval_info(summary, results), indent=2) + "\n", root=Path(output_dir))
