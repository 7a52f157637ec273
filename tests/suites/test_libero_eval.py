"""``molmo-eval benchmark=libero_object``: LIBERO episodes through our workers, results, recording and resume.

Needs the LIBERO venv (``make .libero-venv``); a LIBERO process and each task's first scene cost ~10 s here, so
the default run is two 8-step episodes at 64² images, recorded; the resume after ``kill -9`` of the whole run is
``slow``.
"""

from __future__ import annotations

import html
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from eval_runs import interrupted, molmo_eval
from molmo_lerobot.config import compose
from molmo_lerobot.errors import RunError
from molmo_lerobot.export.merge import read_eval_records
from molmo_lerobot.runner.evaluate import run_evaluation
from molmo_lerobot.suites.libero import libero_venv

needs_libero = pytest.mark.skipif(not (libero_venv() / "bin" / "python").exists(),
                                  reason=f"no LIBERO venv at {libero_venv()} (make .libero-venv builds it)")

ARGS = ["policy=random", "benchmark=libero_object", "workers=1", "horizon=8", "benchmark.image_size=64",
        "progress=false"]


@needs_libero
def test_libero_run_scores_per_task_and_records(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    res = run_evaluation(compose([*ARGS, "limit=2", "record=true", f"output_dir={tmp_path}"]))
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["n_episodes"] == 2 and sorted(doc["per_task"]) == ["libero_object/task_00", "libero_object/task_01"]
    lines = [json.loads(line) for line in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    assert sorted((e["task_type"], e["steps"], e["horizon"], e["seed"], e["error"], e["extra"]["init_state_index"])
                  for e in lines) == [("libero_object/task_00", 8, 8, 0, None, 0),
                                      ("libero_object/task_01", 8, 8, 0, None, 0)]
    assert len({e["extra"]["digest"] for e in lines}) == 2
    assert res.run_summary.n_episodes == 2
    # each task's row carries LIBERO's instruction, and the scores are in lerobot-eval's eval_info.json too
    prompts = {r.task_type: r.prompt for r in res.episodes}
    assert all(prompts.values()) and {t: b["instructions"] for t, b in doc["per_task"].items()} == {
        t: [p] for t, p in prompts.items()}
    info = json.loads((tmp_path / "eval_info.json").read_text())
    assert [(t["task_group"], t["task_id"], t["metrics"]["successes"]) for t in info["per_task"]] == [
        ("libero_object", 0, [False]), ("libero_object", 1, [False])]
    assert info["overall"]["n_episodes"] == 2 and info["overall"]["avg_max_reward"] == doc["avg_max_reward"] == 0.0
    report = (tmp_path / "report.html").read_text()
    assert "Per house" not in report and all(html.escape(p) in report for p in prompts.values())
    # the recording: LeRobot's LIBERO layout at the run's image size, one frame per step, the eval records
    ds = LeRobotDataset("local/x", root=tmp_path / "dataset", video_backend="pyav")
    assert {k: tuple(v["shape"]) for k, v in ds.meta.features.items() if k.startswith(("observation", "action"))} == {
        "observation.images.image": (64, 64, 3), "observation.images.image2": (64, 64, 3),
        "observation.state": (8,), "action": (7,)}
    assert (ds.meta.fps, ds.meta.robot_type, ds.meta.total_frames) == (10, "panda", 16)
    assert ds[8]["task"] == res.episodes[1].prompt
    records = read_eval_records(tmp_path / "dataset")
    assert [(r["episode_index"], r["benchmark_episode_index"], r["steps"]) for r in records] == [(0, 0, 8), (1, 1, 8)]


def _processes() -> dict[int, tuple[int, int, str]]:
    """pid -> (parent pid, process group, command line) of every live (not zombie) process."""
    out = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmd = (stat.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if fields[0] != "Z":
            out[int(stat.parent.name)] = (int(fields[1]), int(fields[2]), cmd)
    return out


def _group(pgid: int) -> dict[int, str]:
    """pid -> command line of every live process in process group ``pgid``, and of the LIBERO processes its
    processes started (each in a group of its own)."""
    procs = _processes()
    group = {pid for pid, (_, g, _) in procs.items() if g == pgid}
    return {pid: cmd for pid, (parent, _, cmd) in procs.items()
            if pid in group or (parent in group and "libero_server" in cmd)}


def _frames(root: Path) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """benchmark episode -> (its recorded 8-D states, its 7-D actions)."""
    import pyarrow.dataset as pads

    table = pads.dataset(str(root / "data"), format="parquet").to_table(
        columns=["episode_index", "observation.state", "action"]).to_pandas()
    bench = {r["episode_index"]: r["benchmark_episode_index"] for r in read_eval_records(root)}
    return {bench[ep]: (np.stack(g["observation.state"].to_numpy()), np.stack(g["action"].to_numpy()))
            for ep, g in table.groupby("episode_index")}


@needs_libero
@pytest.mark.slow
@pytest.mark.timeout(3600)  # three runs of 3 LIBERO episodes: ~25 min on the loaded 2-core machine
def test_libero_run_killed_with_sigkill_resumes_to_the_uninterrupted_run(tmp_path):
    """``molmo-eval … workers=2 record=true``, its whole process group (molmo-eval, its workers; their LIBERO
    processes, each in a group of its own, die with them) SIGKILLed once an episode is done, then
    ``resume=true``: per episode the same results, and the same recorded states and actions bit for bit, as the
    run never cut."""
    args = [a for a in ARGS if a != "workers=1"] + ["workers=2", "limit=3", "record=true"]
    whole = run_evaluation(compose([*args, f"output_dir={tmp_path / 'whole'}"]))

    cut = tmp_path / "cut"
    with open(tmp_path / "cut.log", "w") as log:
        proc = subprocess.Popen([sys.executable, "-m", "molmo_lerobot.cli.eval", *args, f"output_dir={cut}"],
                                stdout=log, stderr=log, start_new_session=True)  # its own process group
    episodes, deadline = cut / "episodes.jsonl", time.monotonic() + 1200
    while proc.poll() is None and time.monotonic() < deadline and not (
            episodes.exists() and episodes.read_text().count("\n") >= 1):
        time.sleep(0.2)
    assert proc.poll() is None, (tmp_path / "cut.log").read_text()[-3000:]
    group = _group(proc.pid)
    assert sum("libero_server" in cmd for cmd in group.values()) == 2, group  # both workers' LIBERO processes
    os.killpg(proc.pid, signal.SIGKILL)
    assert proc.wait() == -signal.SIGKILL

    def left() -> dict[int, str]:
        return {**_group(proc.pid), **{pid: group[pid] for pid in group if pid in _processes()}}

    while left() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert left() == {}
    kept = episodes.read_text().splitlines()
    assert 1 <= len(kept) < 3 and not (cut / "results.json").exists()

    resumed = run_evaluation(compose([*args, "resume=true", f"output_dir={cut}"]))

    def outcomes(res):
        return [(r.episode_index, r.task_type, r.seed, r.success, r.steps, r.error, r.extra["digest"],
                 r.extra["ended_by"]) for r in res.episodes]

    assert outcomes(resumed) == outcomes(whole) and len(whole.episodes) == 3
    ours, theirs = _frames(cut / "dataset"), _frames(tmp_path / "whole" / "dataset")
    assert sorted(ours) == sorted(theirs) == [0, 1, 2]
    for i in ours:
        assert np.array_equal(ours[i][0], theirs[i][0]) and np.array_equal(ours[i][1], theirs[i][1]), i


def test_libero_run_refuses_environment_state_recording_up_front(tmp_path):
    with pytest.raises(RunError, match=r"record_environment_state: env-suite episodes .* have no environment state"):
        run_evaluation(compose([*ARGS, "record=true", "record_environment_state=true", "limit=1",
                                f"output_dir={tmp_path}"]))
    assert not tmp_path.joinpath("episodes.jsonl").exists()


@needs_libero
@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_libero_run_interrupted_resumes_with_the_command_it_prints(tmp_path):
    """Ctrl-C of ``molmo-eval policy=random benchmark=libero_object …`` once an episode is done prints
    ``output_dir=… resume=true``; that command alone finishes the run with its options (policy, benchmark, its
    image size, horizon, seed: none the defaults) and ends as the run never cut."""
    args = [*ARGS, "limit=3", "seed=2"]
    whole = run_evaluation(compose([*args, f"output_dir={tmp_path / 'whole'}"]))
    cut = tmp_path / "cut"
    done = molmo_eval(*interrupted(*args, out=cut, after=1, timeout=1200).split(), timeout=1800)
    assert done.returncode == 0, done.stderr[-3000:]

    def outcomes(rows):
        return sorted((r["episode_index"], r["task_type"], r["seed"], r["success"], r["steps"], r["error"],
                       r["extra"]["digest"]) for r in rows)

    resumed = [json.loads(line) for line in (cut / "episodes.jsonl").read_text().splitlines()]
    assert outcomes(resumed) == outcomes(r.to_dict() for r in whole.episodes) and len(resumed) == 3
