"""report.html (with and without a recorded dataset) and W&B logging (offline)."""

from __future__ import annotations

import json
import re
import time

import export_synthetic as S  # tests/export is on sys.path (pytest's prepend import mode)

from molmo_lerobot.assets.catalog import AssetCatalog
from molmo_lerobot.assets.libraries import BuiltinAssetLibrary
from molmo_lerobot.export.glance import GlanceRecorderFactory, exterior_camera, object_category
from molmo_lerobot.export.recorder import LeRobotRecorderFactory
from molmo_lerobot.export.report import render_report, task_label, write_report
from molmo_lerobot.export.wandb_log import log_run, metrics
from molmo_lerobot.results import EpisodeResult
from molmo_lerobot.run_config import RunConfig


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
    assert "33.3%" in page and "66.7%" in page  # success at the end / at any chunk end
    assert page.count("<svg") == 1 and page.count("<rect") >= 6  # bars: all, open, pick × 2 metrics
    rows = re.findall(r"<tr id=ep(\d+) data-outcome=(\w+)>", page)
    assert rows == [("0", "success"), ("1", "failure"), ("2", "error")]
    assert "&lt;boom&gt;" in page and "<boom>" not in page and "&lt;b&gt;mug" in page
    assert "<video" not in page


def test_report_links_each_episode_to_its_dataset_video_segment(tmp_path):
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    cfg = {"benchmark": {"name": "synth_v1"}, "policy": {"name": "scripted"}, "timing": {"policy_dt_ms": 50.0}}
    factory = LeRobotRecorderFactory.from_config(RunConfig.of(cfg))
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
    summary = S.summary_for(results).model_copy(update={"config": {"wandb": {"enable": True, "project": "molmo-test"}}})
    assert log_run(tmp_path, summary, results) is True
    (run_dir,) = list((tmp_path / "wandb").glob("offline-run-*"))
    (table,) = list(run_dir.glob("files/media/table/episodes_*.table.json"))
    rows = json.loads(table.read_text())["data"]
    assert [r[0] for r in rows] == [0, 1, 2] and [r[4] for r in rows] == [True, False, False]
    log_file = next(run_dir.glob("run-*.wandb"))  # offline: metrics live in the run log,
    deadline = time.monotonic() + 60  # which wandb's service may still be flushing on a loaded machine
    while b"success_once_rate" not in log_file.read_bytes() and time.monotonic() < deadline:
        time.sleep(0.5)
    log_bytes = log_file.read_bytes()
    assert b"pick/success_rate" in log_bytes and b"success_once_rate" in log_bytes

def test_metrics_are_flat_and_per_task():
    m = metrics(S.summary_for(_results()))
    assert m["n_errors"] == 1 and m["open/n_errors"] == 1 and m["pick/success_rate"] == 0.5
    assert "avg_max_reward" not in m  # these episodes carry no rewards
    rewarded = [EpisodeResult(0, None, None, False, False, 9, 0, task_type="pusht/PushT-v0",
                              extra={"sum_reward": 2.0, "max_reward": 0.5})]
    m = metrics(S.summary_for(rewarded))
    assert (m["avg_max_reward"], m["pusht/PushT-v0/avg_sum_reward"]) == (0.5, 2.0)


def test_failures_are_grouped_with_counts_and_breakdowns_per_house_and_category():
    timeouts = [EpisodeResult.failed(i, i % 2, "x.Pick", i, f"TimeoutError: episode {i} ran past {900 + i} s "
                                     "(at local.py:12)", task_type="pick") for i in range(3)]
    never = [EpisodeResult(3 + i, 0, "x.Pick", False, False, 30, 3 + i, task_type="pick") for i in range(2)]
    late = EpisodeResult(5, 1, "x.Pick", False, True, 30, 5, task_type="pick_and_place_next_to",
                         extra={"first_success_step": 10, "object_category": "can"})
    wins = [EpisodeResult(6 + i, 1, "x.Pick", True, True, 30, 6 + i, task_type="pick",
                          extra={"first_success_step": 5 * (i + 1), "object_category": "mug"}) for i in range(4)]
    results = [*timeouts, *never, late, *wins]
    page = render_report(S.summary_for(results).model_copy(update={"timing": {"policy_dt_ms": 100.0}}), results)
    failures = page.split("<h2>Failures</h2>")[1].split("<h2>")[0]
    groups = re.findall(r"<tr id=reason(\d+)><td class=num>F\d+</td><td title='[^']*'>([^<]+)</td>"
                        r"<td class=num>(\d+)</td>", failures)
    assert [(g, n) for _, g, n in groups] == [("error: TimeoutError: episode # ran past # s", "3"),
                                              ("never succeeded", "2"),
                                              ("succeeded at a chunk end, not at the end", "1")]
    assert "6 of 10 episodes failed" in failures
    # each failing row links to its group instead of repeating the reason
    assert re.search(r"<tr id=ep0 data-outcome=error>.*?href=\"#reason1\"", page)
    assert page.count(">error: TimeoutError") == 1
    breakdowns = page.split("<h2>Breakdowns</h2>")[1].split("<h2>")[0]
    assert "Per object category" in breakdowns and "Per house" in breakdowns
    assert re.search(r"<td>mug</td><td class=num>4</td><td class=num>100.0%", breakdowns)
    assert re.search(r"<td>house 0</td><td class=num>4</td><td class=num>0.0%", breakdowns)
    hist = page.split("<h2>Time to first success</h2>")[1].split("<h2>")[0]
    assert "5 of 10 episodes succeeded at some step; median 1.0 s" in hist and "<svg" in hist
    assert "Pick and place next to" in page and 'name=show value=failures' in page


def test_a_suite_report_shows_instructions_and_rewards_and_no_houses():
    results = [EpisodeResult(i, None, None, False, False, 300, 1000 + i, task_type=f"libero_object/task_0{i}",
                             prompt=f"pick up the {obj} and place it in the basket",
                             extra={"sum_reward": 0.0, "max_reward": float(i)})
               for i, obj in enumerate(["alphabet soup", "cream cheese"])]
    page = render_report(S.summary_for(results), results)
    assert "Per house" not in page and "Breakdowns" not in page and "<th>house</th>" not in page
    tasks = page.split("<h2>Per task</h2>")[1].split("<svg")[0]
    assert "<td title='pick up the cream cheese and place it in the basket'>pick up the cream cheese" in tasks
    assert "<th>avg max reward</th>" in tasks and "<td class=num>0.500</td>" in tasks  # overall: mean of 0 and 1
    assert "avg max reward 0.500" in page.split("<h2>")[0]


def test_a_task_with_many_instructions_shows_the_first_and_how_many_more():
    page = render_report(S.summary_for(_results()), _results())
    assert "pick up the &lt;b&gt;mug&lt;/b&gt; <span class=sub>(+1 more)</span>" in page
    assert "avg max reward" not in page  # these episodes carry no rewards


def test_task_labels_are_readable():
    assert task_label("pick_and_place_next_to") == "Pick and place next to"
    assert task_label("molmo_lerobot.tasks.pick_and_place.PickAndPlaceColorTask") == "Pick and place color"
    assert task_label(None) == "unknown"


def test_glance_recorder_saves_first_and_last_frame_and_first_success(tmp_path):
    rec = GlanceRecorderFactory(width=16).make("w0g0", tmp_path)
    info = S.info(4, 10)
    info.extra["object"] = "builtin_grey_can"
    info.catalog = AssetCatalog()  # the run's catalog: the built-in library knows the can
    info.catalog.register_library(BuiltinAssetLibrary())
    assert [s for s in range(10) if rec.wants_images_at(s, 10)] == [0, 9]
    rec.start_episode(info)
    for t in range(10):
        obs = S.obs(4, t) if t in (0, 9) else {**S.obs(4, t), "images": {}}
        rec.record_step(obs, {}, None, t >= 6, t == 9)
    result = EpisodeResult(4, 1, "x.Pick", True, True, 10, 1004, task_type="pick")
    rec.end_episode(result)
    assert result.extra == {"first_success_step": 7, "object_category": "can", "thumbnail": "thumbnails/000004.jpg"}
    import cv2

    img = cv2.imread(str(tmp_path / "thumbnails/000004.jpg"))
    assert img.shape == (12, 34, 3)  # two 16 x 12 frames and a 2 px gap
    first, last = img[:, :16].mean(), img[:, 18:].mean()
    assert first == __import__("pytest").approx((4 * 37) % 250, abs=3)
    assert last == __import__("pytest").approx((4 * 37 + 9 * 5) % 250, abs=3)


def test_exterior_camera_and_object_category_fallbacks():
    assert exterior_camera(["wrist", "exterior"]) == "exterior"
    assert exterior_camera(["wrist_cam", "front"]) == "front"
    assert exterior_camera([]) is None
    assert object_category("Mug_17", None) == "mug" and object_category(None, None) is None
