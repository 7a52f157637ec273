"""report.html (with and without a recorded dataset) and W&B logging (offline)."""

from __future__ import annotations

import json
import re

import export_synthetic as S  # tests/export is on sys.path (pytest's prepend import mode)
from molmo_lerobot.export.recorder import LeRobotRecorderFactory
from molmo_lerobot.export.report import write_report
from molmo_lerobot.export.wandb_log import log_run, metrics
from molmo_lerobot.runner.results import EpisodeResult


def _results():
    return [
        EpisodeResult(0, 1, "x.Pick", True, True, 30, 11, task_type="pick", prompt="pick up the <b>mug</b>"),
        EpisodeResult(1, 1, "x.Pick", False, True, 30, 12, task_type="pick", prompt="pick up the can"),
        EpisodeResult.failed(2, 2, "x.Open", 13, "RuntimeError: <boom>", task_type="open"),
    ]


def test_report_without_recording_has_scores_plot_and_a_row_per_episode(tmp_path):
    results = _results()
    path = write_report(tmp_path, S.summary_for(results), results)
    page = path.read_text()
    assert path.name == "report.html"
    assert "33.3%" in page and "66.7%" in page  # success at the end / at any step
    assert page.count("<svg") == 1 and page.count("<rect") >= 6  # bars: all, open, pick × 2 metrics
    rows = re.findall(r"<tr><td class=num>(\d+)</td>", page)
    assert rows == ["0", "1", "2"]
    assert "&lt;boom&gt;" in page and "<boom>" not in page and "&lt;b&gt;mug" in page
    assert "<video" not in page


def test_report_links_each_episode_to_its_dataset_video_segment(tmp_path):
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    cfg = {"benchmark": {"name": "synth_v1"}, "policy": {"name": "scripted"}, "timing": {"policy_dt_ms": 50.0}}
    factory = LeRobotRecorderFactory.from_config(cfg)
    w = factory.make("w0g0", tmp_path)
    results = [S.run_episode(w, 0, 10, 4), S.run_episode(w, 1, 6, None, error="ValueError: x"),
               S.run_episode(w, 2, 20, 1)]
    w.close()
    summary = S.summary_for(results)
    factory.finalize(tmp_path, results, summary)
    page = write_report(tmp_path, summary, results).read_text()
    clips = re.findall(r'<video src="([^"#]+)#t=([\d.]+),([\d.]+)" title="(\w+)"', page)
    assert len(clips) == 4  # 2 recorded episodes × 2 cameras; the errored one has none
    meta = LeRobotDatasetMetadata(factory.repo_id, root=tmp_path / "dataset")
    assert {(float(a), float(b)) for _, a, b, _ in clips} == {(0.0, 0.5), (0.5, 1.5)}  # 10 and 20 frames at 20 fps
    for src, _, _, cam in clips:
        assert (tmp_path / src).is_file() and cam in ("exo", "wrist")
    assert meta.total_episodes == 2


def test_wandb_is_off_by_default(tmp_path):
    results = _results()
    assert log_run(tmp_path, S.summary_for(results), results) is False
    assert not (tmp_path / "wandb").exists()


def test_wandb_offline_run_records_the_scores(tmp_path, monkeypatch):
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    results = _results()
    summary = S.summary_for(results)
    summary["config"] = {"wandb": {"enable": True, "project": "molmo-test"}}
    assert log_run(tmp_path, summary, results) is True
    (run_dir,) = list((tmp_path / "wandb").glob("offline-run-*"))
    (table,) = list(run_dir.glob("files/media/table/episodes_*.table.json"))
    rows = json.loads(table.read_text())["data"]
    assert [r[0] for r in rows] == [0, 1, 2] and [r[4] for r in rows] == [True, False, False]
    log_bytes = next(run_dir.glob("run-*.wandb")).read_bytes()  # offline: metrics live in the run log
    assert b"pick/success_rate" in log_bytes and b"success_once_rate" in log_bytes

def test_metrics_are_flat_and_per_task():
    m = metrics(S.summary_for(_results()))
    assert m["n_errors"] == 1 and m["open/n_errors"] == 1 and m["pick/success_rate"] == 0.5
