"""Export overhead, measured in one run (``pytest -m perf -s tests/perf/test_export_overhead.py``).

Three ``run_evaluation`` runs of the same pick_v1 episodes (scripted expert, workers=2):

* ``eval``: no recorder. The scripted expert needs no images, so nothing is rendered;
* ``render``: a recorder that only asks for images, so every step renders every camera
  (what any image-based policy or video recording pays anyway) and keeps nothing;
* ``export``: ``record=true``: every step rendered, streamed into per-worker LeRobot shards
  (AV1 streaming encoding), merged into ``output_dir/dataset`` at the end.

Reported: export/eval and export/render wall-time ratios (target <= 1.15 against the
rendering eval). Figures are printed and appended to ``runs/perf.jsonl``; nothing is
asserted about speed, only that the exported dataset is complete.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

from molmo_lerobot.config import compose
from molmo_lerobot.plugins import get_plugins
from molmo_lerobot.runner import evaluate
from molmo_lerobot.runner.recorders import Recorder, RecorderFactory

pytestmark = pytest.mark.perf
N_EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "6"))
HORIZON = os.environ.get("MOLMO_PERF_HORIZON")  # default: the task's own horizon
WORKERS = int(os.environ.get("MOLMO_PERF_WORKERS", "2"))


class RenderOnlyRecorder(Recorder):
    """Makes the rollout render every camera at every step, and keeps nothing."""

    wants_images = True

    def __init__(self) -> None:
        self.frames = 0

    def start_episode(self, info) -> None: ...

    def record_step(self, obs, action, reward, success, done) -> None:
        self.frames += len(obs["images"])

    def end_episode(self, result) -> None: ...


class RenderOnlyFactory(RecorderFactory):
    def make(self, worker_id, output_dir):
        return RenderOnlyRecorder()


def _run(out: Path, *extra: str) -> tuple[float, dict]:
    overrides = ["policy=scripted", "benchmark=pick_v1", f"workers={WORKERS}", f"limit={N_EPISODES}",
                 "progress=false", f"output_dir={out}", *extra]
    if HORIZON:
        overrides.append(f"horizon={HORIZON}")
    cfg = compose(overrides)
    t0 = time.perf_counter()
    res = evaluate.run_evaluation(cfg)
    return time.perf_counter() - t0, res.summary


def test_export_overhead(tmp_path, monkeypatch):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    _run(tmp_path / "warmup", "limit=1", "horizon=5", "record=true")  # warm the file cache and imports
    t_eval, summary = _run(tmp_path / "eval")
    with monkeypatch.context() as m:  # a recorder that only asks for images, through the plugin hook
        m.setattr(get_plugins(), "recorder_factories", lambda cfg: [RenderOnlyFactory()])
        t_render, _ = _run(tmp_path / "render")
    t_export, _ = _run(tmp_path / "export", "record=true")

    ds = LeRobotDataset("local/pick_v1-scripted", root=tmp_path / "export" / "dataset", video_backend="pyav")
    ok = N_EPISODES - summary["n_errors"]
    assert ds.num_episodes == ok
    steps = sum(json.loads(line)["steps"] for line in (tmp_path / "export" / "episodes.jsonl").read_text().splitlines())
    assert ds.num_frames == steps

    figures = {
        "benchmark": "export_overhead", "episodes": N_EPISODES, "workers": WORKERS, "frames": ds.num_frames,
        "cameras": len(ds.meta.video_keys), "eval_s": round(t_eval, 2), "render_s": round(t_render, 2),
        "export_s": round(t_export, 2), "export_over_eval": round(t_export / t_eval, 3),
        "export_over_render": round(t_export / t_render, 3), "target_export_over_render": 1.15,
    }
    line = json.dumps(figures)
    print("\n" + line)
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        f.write(line + "\n")
