"""``molmo-eval benchmark=libero_object``: LIBERO episodes through our workers, results and resume.

Needs the LIBERO venv (``make .libero-venv``); each LIBERO reset costs ~10 s here, so the default run is two
8-step episodes at 64² images; the resume (a run cut after its first episode, resumed to two) is ``slow``.
"""

from __future__ import annotations

import json

import pytest

from molmo_lerobot.config import compose
from molmo_lerobot.errors import RunError
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.suites.libero import libero_venv

needs_libero = pytest.mark.skipif(not (libero_venv() / "bin" / "python").exists(),
                                  reason=f"no LIBERO venv at {libero_venv()} (make .libero-venv builds it)")

ARGS = ["policy=random", "benchmark=libero_object", "workers=1", "horizon=8", "benchmark.image_size=64",
        "progress=false"]


@needs_libero
def test_libero_run_scores_per_task(tmp_path):
    res = run_evaluation(compose([*ARGS, "limit=2", f"output_dir={tmp_path}"]))
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["n_episodes"] == 2 and sorted(doc["per_task"]) == ["libero_object/task_00", "libero_object/task_01"]
    lines = [json.loads(line) for line in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    assert sorted((e["task_type"], e["steps"], e["horizon"], e["seed"], e["error"], e["extra"]["init_state_index"])
                  for e in lines) == [("libero_object/task_00", 8, 8, 0, None, 0),
                                      ("libero_object/task_01", 8, 8, 0, None, 0)]
    assert len({e["extra"]["digest"] for e in lines}) == 2
    assert res.run_summary.n_episodes == 2


@needs_libero
@pytest.mark.slow
def test_libero_run_resumes_after_a_cut(tmp_path):
    out = tmp_path / "run"
    first = run_evaluation(compose([*ARGS, "limit=1", f"output_dir={out}"]))
    assert [(r.task_type, r.steps, r.error) for r in first.episodes] == [("libero_object/task_00", 8, None)]
    kept = (out / "episodes.jsonl").read_text().splitlines()

    res = run_evaluation(compose([*ARGS, "limit=2", "resume=true", f"output_dir={out}"]))
    lines = (out / "episodes.jsonl").read_text().splitlines()
    assert lines[:1] == kept and len(lines) == 2  # episode 0 kept as it was, episode 1 run once
    doc = json.loads((out / "results.json").read_text())
    assert doc["n_episodes"] == 2 and json.loads(lines[1])["task_type"] == "libero_object/task_01"
    assert res.run_summary.n_episodes == 2 and not any(r.error for r in res.episodes)


def test_libero_run_refuses_recording_up_front(tmp_path):
    with pytest.raises(RunError, match="record=true: recording env-suite episodes"):
        run_evaluation(compose([*ARGS, "record=true", "limit=1", f"output_dir={tmp_path}"]))
    assert not tmp_path.joinpath("episodes.jsonl").exists()
