"""``eval_info.json`` from a run's results: ``lerobot-eval``'s structure, errors, our benchmarks' task rows.

Its numbers against ``lerobot-eval``'s own are ``tests/suites/test_eval_info_parity.py``."""

from __future__ import annotations

import json
import math

import export_synthetic as S  # tests/export is on sys.path (pytest's prepend import mode)

from molmo_lerobot.export.eval_info import eval_info, write_eval_info
from molmo_lerobot.results import EpisodeResult, summarize


def _suite_episode(i: int, task_id: int, success: bool, rewards: tuple[float, float] | None) -> EpisodeResult:
    extra = {"success_any_step": success, "suite": "libero_object", "task_id": task_id, "init_state_index": i}
    if rewards is not None:
        extra.update(sum_reward=rewards[0], max_reward=rewards[1])
    return EpisodeResult(i, None, None, success, success, 5, 1000 + i, task_type=f"libero_object/task_{task_id:02d}",
                         prompt=f"task {task_id}", extra=extra)


def test_a_suite_run_is_written_in_lerobot_evals_structure(tmp_path):
    results = [_suite_episode(0, 3, True, (1.0, 1.0)), _suite_episode(1, 3, False, (0.0, 0.0)),
               _suite_episode(2, 1, False, (0.0, 0.0)),
               EpisodeResult.failed(3, None, None, 1003, "SuiteError: step: boom", task_type="libero_object/task_01")]
    summary = summarize(results, benchmark={"name": "libero_object"}, wall_time_s=8.0)
    doc = json.loads(write_eval_info(tmp_path, summary, results).read_text())
    assert list(doc) == ["per_task", "per_group", "overall"]
    # one row per task in task-id order, LIBERO's task id, its episodes' lists in episode order
    assert [(t["task_group"], t["task_id"], t["task"]) for t in doc["per_task"]] == [
        ("libero_object", 1, "libero_object/task_01"), ("libero_object", 3, "libero_object/task_03")]
    first = doc["per_task"][0]["metrics"]
    assert first == {"sum_rewards": [0.0, None], "max_rewards": [0.0, None], "successes": [False, False],
                     "video_paths": [], "predicted_video_paths": []}  # the errored episode: a failure, no rewards
    group = doc["per_group"]["libero_object"]
    assert list(group) == ["avg_sum_reward", "avg_max_reward", "pc_success", "n_episodes", "video_paths",
                           "predicted_video_paths"]
    # rewards average the 3 episodes that ran (nanmean); success counts all 4, the error a failure
    assert (group["avg_sum_reward"], group["avg_max_reward"], group["pc_success"], group["n_episodes"]) == (
        1 / 3, 1 / 3, 25.0, 4)
    overall = doc["overall"]
    assert list(overall) == ["avg_sum_reward", "avg_max_reward", "pc_success", "n_episodes", "eval_s", "eval_ep_s",
                             "video_paths", "predicted_video_paths"]
    assert (overall["eval_s"], overall["eval_ep_s"], overall["pc_success"]) == (8.0, 2.0, 25.0)


def test_success_is_any_step_as_lerobot_eval_counts_it():
    """lerobot-eval counts an episode as a success if any step succeeded, whatever its last state."""
    late = EpisodeResult(0, 1, "x.Pick", False, True, 30, 0, task_type="pick", extra={"success_any_step": True,
                                                                                     "sum_reward": 3.0,
                                                                                     "max_reward": 1.0})
    doc = eval_info(S.summary_for([late]), [late])
    assert doc["overall"]["pc_success"] == 100.0 and S.summary_for([late]).success_rate == 0.0


def test_our_benchmarks_rows_are_the_benchmarks_task_types():
    def episode(i: int, task: str) -> EpisodeResult:
        won = i == 0
        return EpisodeResult(i, 1, "x.Pick", won, won, 30, i, task_type=task, prompt=f"p{i}",
                             extra={"success_any_step": won, "sum_reward": float(won), "max_reward": float(won)})

    results = [episode(i, task) for i, task in enumerate(["pick", "open", "pick"])]
    doc = eval_info(S.summary_for(results), results)
    assert [(t["task_group"], t["task_id"], t["task"]) for t in doc["per_task"]] == [("synth_v1", 0, "open"),
                                                                                    ("synth_v1", 1, "pick")]
    assert doc["per_task"][1]["metrics"]["successes"] == [True, False]
    assert list(doc["per_group"]) == ["synth_v1"] and doc["overall"]["n_episodes"] == 3


def test_a_run_in_which_nothing_ran_has_null_averages_not_nan():
    results = [EpisodeResult.failed(0, 1, "x.Pick", 0, "RuntimeError: boom", task_type="pick")]
    doc = eval_info(S.summary_for(results), results)
    text = json.dumps(doc, allow_nan=False)  # standard JSON: lerobot-eval writes NaN here
    assert doc["overall"]["avg_max_reward"] is None and doc["overall"]["pc_success"] == 0.0 and text
    assert not any(isinstance(v, float) and math.isnan(v) for v in doc["overall"].values())
