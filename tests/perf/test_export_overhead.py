"""Export overhead, measured in one run (``pytest -m perf -s tests/perf/test_export_overhead.py``).

Five ``run_evaluation`` runs of the same pick_v1 episodes (scripted expert, workers=2):

* ``eval``: no recorder. The scripted expert needs no images, so nothing is rendered;
* ``render``: a recorder that only asks for images, so every step renders every camera
  (what any image-based policy or video recording pays anyway) and keeps nothing;
* ``export``: ``record=true record_hold_steps=null`` with the default ``video`` settings
  (LeRobot's AV1): every step rendered, streamed into per-worker LeRobot shards, merged into
  ``output_dir/dataset``;
* ``export_h264``: the same with ``video.vcodec=h264``; left out with ``MOLMO_PERF_H264=0``;
* ``export_held``: plain ``record=true``: the expert's recording ends 10 steps after its first
  success, so the rest of the rollout is neither rendered nor encoded.

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
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.recording import Recorder, RecorderFactory
from molmo_lerobot.runner import evaluate

pytestmark = [pytest.mark.perf, pytest.mark.timeout(7200)]  # MOLMO_PERF_EPISODES=60: ~20 min
N_EPISODES = int(os.environ.get("MOLMO_PERF_EPISODES", "6"))
HORIZON = os.environ.get("MOLMO_PERF_HORIZON")  # default: the task's own horizon
WORKERS = int(os.environ.get("MOLMO_PERF_WORKERS", "2"))
H264 = os.environ.get("MOLMO_PERF_H264", "1") != "0"


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
        m.setattr(Plugins, "recorder_factories", lambda self, cfg: [RenderOnlyFactory()])
        t_render, _ = _run(tmp_path / "render")
    t_export, _ = _run(tmp_path / "export", "record=true", "record_hold_steps=null")
    t_h264 = (_run(tmp_path / "export_h264", "record=true", "record_hold_steps=null", "video.vcodec=h264")[0]
              if H264 else None)
    t_held, _ = _run(tmp_path / "export_held", "record=true")

    steps = sum(json.loads(line)["steps"] for line in (tmp_path / "eval" / "episodes.jsonl").read_text().splitlines())
    mb = {}
    for name in ("export", "export_h264")[: 2 if H264 else 1]:
        root = tmp_path / name / "dataset"
        ds = LeRobotDataset("local/pick_v1-scripted", root=root, video_backend="pyav")
        assert ds.num_episodes == N_EPISODES - summary["n_errors"] and ds.num_frames == steps
        mb[name] = round(sum(p.stat().st_size for p in (root / "videos").rglob("*.mp4")) / 2**20, 2)

    figures = {
        "benchmark": "export_overhead", "episodes": N_EPISODES, "workers": WORKERS, "frames": ds.num_frames,
        "cameras": len(ds.meta.video_keys), "eval_s": round(t_eval, 2), "render_s": round(t_render, 2),
        "export_s": round(t_export, 2), "export_over_eval": round(t_export / t_eval, 3),
        "export_over_render": round(t_export / t_render, 3), "target_export_over_render": 1.15,
        "video_mb": mb["export"], "export_held_s": round(t_held, 2),
        "held_frames": LeRobotDataset("local/pick_v1-scripted", root=tmp_path / "export_held" / "dataset",
                                      video_backend="pyav").num_frames,
    }
    if t_h264 is not None:
        figures |= {"export_h264_s": round(t_h264, 2), "export_h264_over_render": round(t_h264 / t_render, 3),
                    "video_h264_mb": mb["export_h264"]}
    line = json.dumps(figures)
    print("\n" + line)
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        f.write(line + "\n")
