"""RunSummary owns results.json: a round trip keeps every field, results.json files written by older code
(tests/data/results: ``main-39d7815.json`` from ``molmo-eval policy=scripted benchmark=pick_v1 workers=2 seed=0
limit=4`` on main at 39d7815, paths shortened; ``first-b698168.json`` from the first summarize, b698168, before
``n_valid``, ``error_kind``, ``start_warnings``, ``output_errors``, ``code`` …) still read, and a malformed one
is refused with one line naming the file and field. read_run is the one reader of a run directory."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from molmo_lerobot.cli.compare import main as compare_main
from molmo_lerobot.results import (
    SCHEMA_VERSION,
    EpisodeResult,
    Push,
    RunFileError,
    RunSummary,
    read_episodes,
    read_run,
    summarize,
    summary_lines,
)

DATA = Path(__file__).parents[1] / "data" / "results"
OLD = ["main-39d7815.json", "first-b698168.json"]


def _results():
    return [EpisodeResult(0, 1, "x.Pick", True, True, 30, 11, task_type="pick", prompt="pick up the mug"),
            EpisodeResult(1, 1, "x.Pick", False, True, 30, 12, task_type="pick",
                          output_errors=["GlanceRecorder: OSError: disk full"]),
            EpisodeResult.failed(2, 2, "x.Open", 13, "RuntimeError: boom", task_type="open")]


def _run_dir(path: Path, summary: RunSummary, results: list[EpisodeResult]) -> Path:
    path.mkdir()
    (path / "results.json").write_text(summary.to_json())
    (path / "episodes.jsonl").write_text("".join(json.dumps(r.to_dict()) + "\n" for r in results))
    return path


def test_a_summary_round_trips_through_its_file(tmp_path):
    summary = summarize(_results(), benchmark={"name": "b", "sha256": "ab" * 32, "n_episodes": 9, "path": "/b"},
                        policy={"name": "p", "act_sleep_s": 0.0}, seed=0, limit=None, thresholds={"pick": {"k": 1}})
    summary = summary.with_piece(Push(repo_id="ns/name", ok=False, error="HTTP 500"))
    (tmp_path / "results.json").write_text(summary.to_json())
    again = RunSummary.read(tmp_path / "results.json")
    assert again == summary and again.to_json() == summary.to_json()
    doc = again.document()
    assert doc["schema_version"] == SCHEMA_VERSION and doc["limit"] is None  # set to null: written as null
    assert "horizon" not in doc and "export_errors" not in doc  # never set: not written
    assert doc["push"] == {"repo_id": "ns/name", "ok": False, "error": "HTTP 500"}
    assert doc["per_task"]["open"]["success_rate"] is None and doc["per_task"]["pick"]["ci95"][1] <= 1.0
    assert doc["output_errors"] == [{"episode_index": 1, "errors": ["GlanceRecorder: OSError: disk full"]}]


def test_per_task_rows_carry_their_instructions_and_rewards_averaged_over_the_episodes_that_ran(tmp_path):
    def pusht(i: int, sum_reward: float, max_reward: float) -> EpisodeResult:
        return EpisodeResult(i, None, None, False, False, 300, i, task_type="pusht/PushT-v0", prompt="",
                             extra={"sum_reward": sum_reward, "max_reward": max_reward})

    results = [pusht(0, 12.0, 0.5), pusht(1, 3.0, 0.25),
               EpisodeResult.failed(2, None, None, 2, "RuntimeError: boom", task_type="pusht/PushT-v0"),
               *_results()]
    summary = summarize(results)
    (tmp_path / "results.json").write_text(summary.to_json())
    doc = RunSummary.read(tmp_path / "results.json").document()
    row = doc["per_task"]["pusht/PushT-v0"]
    assert (row["avg_sum_reward"], row["avg_max_reward"], row["n_episodes"]) == (7.5, 0.375, 3)  # the error: no reward
    assert row["instructions"] == [""]  # lerobot-eval gives PushT an empty task
    assert doc["per_task"]["pick"]["instructions"] == ["pick up the mug"]  # each once; none for the one without
    assert "avg_max_reward" not in doc["per_task"]["pick"]  # its episodes carry no rewards (written before them)
    assert doc["avg_max_reward"] == 0.375 and "instructions" not in doc
    assert summary_lines(summary)[0].endswith("avg max reward 0.375")
    assert "  pusht/PushT-v0: 0.000 (0/3, 1 errored), avg max reward 0.375" in summary_lines(summary)


@pytest.mark.parametrize("name", OLD)
def test_results_written_by_older_code_read_and_write_back_unchanged(name):
    doc = json.loads((DATA / name).read_text())
    summary = RunSummary.from_document(doc)
    assert summary.schema_version == 1 and "schema_version" not in doc
    assert summary.document() == doc  # nothing lost, nothing added
    assert summary.benchmark is not None and summary.benchmark.name == "pick_v1"
    assert summary_lines(summary)[0].startswith(("pick_v1 · scripted: success",
                                                 "1 of 3 episodes errored · pick_v1 · scripted: success"))


def test_a_fresh_summary_has_every_field_of_mains_results_json():
    """The fields main wrote are the model's fields (plus schema_version and the later robots): none left to
    the extras."""
    doc = json.loads((DATA / OLD[0]).read_text())
    summary = RunSummary.from_document(doc)
    assert summary.model_extra == {}
    assert set(RunSummary.model_fields) - set(doc) == {"schema_version", "push", "export_errors", "parity_notes",
                                                       "avg_sum_reward", "avg_max_reward", "robots"}


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d.update(n_success="4"), r"field n_success: Input should be a valid integer \(\"4\"\)"),
    (lambda d: d.update(success_rate=True), r"field success_rate: Input should be a valid number \(true\)"),
    (lambda d: d.pop("per_task"), r"field per_task: Field required$"),
    (lambda d: d["per_task"]["pick"].update(ci95=[0.1, 0.2, 0.3]), r"field per_task\.pick\.ci95: Tuple should "),
    (lambda d: d["per_task"]["pick"].update(n_sucess=1), r"field per_task\.pick\.n_sucess: Extra inputs "),
    (lambda d: d.update(errors=[{"episode_index": 1}]), r"field errors\.0\.error: Field required$"),
    (lambda d: d["benchmark"].pop("name"), r"field benchmark\.name: Field required$"),
    (lambda d: d.update(schema_version=SCHEMA_VERSION + 1),
     rf"schema_version {SCHEMA_VERSION + 1} is newer than this molmo-lerobot"),
])
def test_a_malformed_results_json_is_one_line_naming_the_field(tmp_path, edit, message):
    doc = json.loads((DATA / OLD[0]).read_text())
    edit(doc)
    path = tmp_path / "results.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(RunFileError, match=rf"^{path}: {message}") as info:
        RunSummary.read(path)
    assert len(str(info.value).splitlines()) == 1


def test_summarize_refuses_a_field_results_json_does_not_have():
    with pytest.raises(TypeError, match=r"no results\.json field polcy"):
        summarize(_results(), polcy={"name": "p"})


def test_read_run_reads_both_files_and_names_a_bad_record(tmp_path):
    results = _results()
    summary = summarize(results, benchmark={"name": "b", "sha256": "ab" * 32}, policy={"name": "p"}, seed=0)
    run = read_run(_run_dir(tmp_path / "run", summary, results))
    assert run.summary == summary and run.episodes == results
    episodes = tmp_path / "run" / "episodes.jsonl"
    lines = episodes.read_text().splitlines()
    for bad, why in ((lines[1].replace('"horizon": null', '"horizon": "long"'), "field 'horizon' is \"long\""),
                     (lines[1].replace('"steps": 30', '"steps": true'), "field 'steps' is true"),
                     (lines[0], "episode 0 is recorded twice (also line 1)")):
        episodes.write_text("\n".join([lines[0], bad, lines[2]]) + "\n")
        with pytest.raises(RunFileError) as info:
            read_run(tmp_path / "run")
        assert str(info.value).startswith(f"{episodes}:2: ") and why in str(info.value)


def test_a_torn_last_line_is_dropped_only_for_a_run_being_resumed(tmp_path):
    results = _results()
    path = tmp_path / "episodes.jsonl"
    path.write_text("".join(json.dumps(r.to_dict()) + "\n" for r in results[:2]) + '{"episode_index": 2, "hou')
    assert read_episodes(path, torn_tail=True) == results[:2]
    with pytest.raises(RunFileError, match=rf"^{path}:3: corrupt episode record \(not valid JSON"):
        read_episodes(path)
    unfinished = read_run(tmp_path, finished=False)  # no results.json: a resume reads its episodes only
    assert unfinished.summary is None and unfinished.episodes == results[:2]
    with pytest.raises(RunFileError, match=r"no results.json \(unfinished run\? complete it with resume=true\)"):
        read_run(tmp_path)


def test_molmo_compare_exits_2_with_one_line_for_a_bad_run(tmp_path, capsys):
    results = _results()
    summary = summarize(results, benchmark={"name": "b", "sha256": "ab" * 32}, policy={"name": "p"}, seed=0)
    a = _run_dir(tmp_path / "a", summary, results)
    b = _run_dir(tmp_path / "b", summary, results)
    assert compare_main([str(a), str(b)]) == 0
    capsys.readouterr()
    doc = summary.document()
    (b / "results.json").write_text(json.dumps({**doc, "n_errors": None}))
    assert compare_main([str(a), str(b)]) == 2
    assert capsys.readouterr().err == (f"molmo-compare: error: {b / 'results.json'}: field n_errors: Input should "
                                       "be a valid integer (null)\n")


def test_molmo_compare_refuses_a_record_that_resume_refuses(tmp_path, capsys):
    """molmo-compare read episodes.jsonl with a looser check than resume: a ``"success": "no"`` counted
    as a success (truthy), a record without its seed paired silently. Both read records one way now."""
    doc = json.loads((DATA / OLD[0]).read_text())
    record = {"episode_index": 0, "house_index": 0, "task_cls": "x.Pick", "success": True, "success_once": True,
              "steps": 30, "seed": 11, "error": None, "task_type": "pick"}
    runs = []
    for name, bad in (("a", {}), ("b", {"success": "no"}), ("c", {"seed": None})):
        run = tmp_path / name
        run.mkdir()
        (run / "results.json").write_text(json.dumps(doc))
        (run / "episodes.jsonl").write_text(json.dumps({**record, **bad}) + "\n")
        runs.append(run)
    for run, field in ((runs[1], "success"), (runs[2], "seed")):
        assert compare_main([str(runs[0]), str(run)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"molmo-compare: error: {run / 'episodes.jsonl'}:1: ") and f"field {field!r}" in err
        assert err.count("\n") == 1
