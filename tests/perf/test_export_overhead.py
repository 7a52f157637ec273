"""Export overhead, measured in one run (``pytest -m perf -s tests/perf/test_export_overhead.py``).

Four ``run_evaluation`` runs of the same pick_v1 episodes (scripted expert, workers=2):

* ``eval``: no recorder. The scripted expert needs no images, so nothing is rendered;
* ``render``: a recorder that only asks for images, so every step renders every camera
  (what any image-based policy or video recording pays anyway) and keeps nothing;
* ``export``: ``record=true`` with the default ``video`` settings (h264): every step
  rendered, streamed into per-worker LeRobot shards, merged into ``output_dir/dataset``;
* ``export_av1``: the same with ``video.vcodec=libsvtav1`` (LeRobot's default codec);
  left out with ``MOLMO_PERF_AV1=0``.

Reported: export/eval and export/render wall-time ratios (target <= 1.15 against the
rendering eval) and the size of the videos. Figures are printed and appended to
``runs/perf.jsonl``; nothing is asserted about speed, only that the datasets are complete.
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

pytestmark = [pytest.mark.perf, pytest.mark.timeout(7200)]  # MOLMO_PERF_EPISODES=60: ~20 min
N_EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "6"))
HORIZON = os.environ.get("MOLMO_PERF_HORIZON")  # default: the task's own horizon
WORKERS = int(os.environ.get("MOLMO_PERF_WORKERS", "2"))
AV1 = os.environ.get("MOLMO_PERF_AV1", "1") != "0"


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
    t_av1 = _run(tmp_path / "export_av1", "record=true", "video.vcodec=libsvtav1")[0] if AV1 else None

    steps = sum(json.loads(line)["steps"] for line in (tmp_path / "eval" / "episodes.jsonl").read_text().splitlines())
    mb = {}
    for name in ("export", "export_av1")[: 2 if AV1 else 1]:
        root = tmp_path / name / "dataset"
        ds = LeRobotDataset("local/pick_v1-scripted", root=root, video_backend="pyav")
        assert ds.num_episodes == N_EPISODES - summary["n_errors"] and ds.num_frames == steps
        mb[name] = round(sum(p.stat().st_size for p in (root / "videos").rglob("*.mp4")) / 2**20, 2)

    figures = {
        "benchmark": "export_overhead", "episodes": N_EPISODES, "workers": WORKERS, "frames": ds.num_frames,
        "cameras": len(ds.meta.video_keys), "eval_s": round(t_eval, 2), "render_s": round(t_render, 2),
        "export_s": round(t_export, 2), "export_over_eval": round(t_export / t_eval, 3),
        "export_over_render": round(t_export / t_render, 3), "target_export_over_render": 1.15,
        "video_mb": mb["export"],
    }
    if t_av1 is not None:
        figures |= {"export_av1_s": round(t_av1, 2), "export_av1_over_render": round(t_av1 / t_render, 3),
                    "video_av1_mb": mb["export_av1"]}
    line = json.dumps(figures)
    print("\n" + line)
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        f.write(line + "\n")
