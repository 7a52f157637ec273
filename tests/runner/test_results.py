import math

import pytest

from molmo_lerobot.results import EpisodeResult, summarize, wilson_ci


@pytest.mark.parametrize(
    ("k", "n", "lo", "hi"),
    [(8, 10, 0.4902, 0.9433), (0, 10, 0.0, 0.2775), (10, 10, 0.7225, 1.0), (50, 100, 0.4038, 0.5962)],
)
def test_wilson_matches_reference_values(k, n, lo, hi):
    got = wilson_ci(k, n)
    assert math.isclose(got[0], lo, abs_tol=1e-4) and math.isclose(got[1], hi, abs_tol=1e-4)


def test_wilson_empty_is_uninformative():
    assert wilson_ci(0, 0) == (0.0, 1.0)


def test_summary_counts_errors_as_failures_and_splits_tasks():
    rs = [
        EpisodeResult(0, 1, "a.Pick", True, True, 10, 1, task_type="pick"),
        EpisodeResult(1, 1, "a.Pick", False, True, 10, 2, task_type="pick"),
        EpisodeResult.failed(2, 2, "a.Open", 3, "RuntimeError: boom", task_type="open"),
    ]
    s = summarize(rs, seed=0).document()
    assert s["n_episodes"] == 3 and s["n_success"] == 1 and s["n_errors"] == 1
    assert s["success_rate"] == pytest.approx(1 / 3)
    assert s["success_once_rate"] == pytest.approx(2 / 3)
    assert s["per_task"]["pick"]["n_episodes"] == 2
    assert s["per_task"]["open"]["n_errors"] == 1
    assert s["errors"] == [{"episode_index": 2, "error": "RuntimeError: boom", "error_kind": "episode"}]
    assert s["seed"] == 0


def test_episode_result_roundtrip_keeps_contract_fields():
    r = EpisodeResult(3, 7, "x.Pick", True, True, 303, 42, task_type="pick")
    d = r.to_dict()
    for key in ("episode_index", "house_index", "task_cls", "success", "success_once", "steps", "seed", "error"):
        assert key in d
    assert EpisodeResult.from_dict(d) == r


def test_no_episode_simulated_is_no_score_but_honest_counts():
    from molmo_lerobot.results import summary_lines

    rs = [EpisodeResult.failed(i, 1, "a.Pick", i, "RuntimeError: boom", task_type="pick") for i in range(3)]
    summary = summarize(rs, benchmark={"name": "b"}, policy={"name": "p"})
    s = summary.document()
    assert (s["n_episodes"], s["n_valid"], s["n_errors"], s["n_success"]) == (3, 0, 3, 0)
    assert s["success_rate"] is None and s["success_once_rate"] is None and s["ci95"] is None
    assert s["per_task"]["pick"]["success_rate"] is None
    lines = summary_lines(summary)
    assert lines[0] == "no episode ran: 3 of 3 episodes errored · b · p: no score"
    assert not any("0.000" in ln for ln in lines)


def test_errors_lead_the_headline_and_tasks_without_a_valid_episode_have_no_rate():
    from molmo_lerobot.results import summary_lines

    rs = [EpisodeResult(0, 1, "a.Pick", True, True, 10, 1, task_type="pick"),
          EpisodeResult.failed(1, 2, "a.Open", 3, "RuntimeError: boom", task_type="open")]
    summary = summarize(rs, benchmark={"name": "b"}, policy={"name": "p"})
    s = summary.document()
    assert s["n_valid"] == 1 and s["success_rate"] == 0.5
    assert s["per_task"]["open"]["success_rate"] is None and s["per_task"]["pick"]["n_valid"] == 1
    lines = summary_lines(summary)
    assert lines[0].startswith("1 of 2 episodes errored · b · p: success 0.500")
    assert "  open: no episode ran (0/1, 1 errored)" in lines


def test_infrastructure_errors_and_output_failures_are_told_apart():
    """A dead worker is an infrastructure error (rerun by resume, and the summary says so); a
    thumbnail that could not be written leaves the outcome and is listed on its own."""
    from molmo_lerobot.results import summary_lines

    kept = EpisodeResult(0, 1, "a.Pick", True, True, 10, 1, task_type="pick",
                         output_errors=["GlanceRecorder: OSError: [Errno 28] No space left on device"])
    died = EpisodeResult.failed(1, 1, "a.Pick", 2, "worker process died with signal SIGKILL", "infrastructure",
                                task_type="pick")
    raised = EpisodeResult.failed(2, 1, "a.Pick", 3, "RuntimeError: boom", task_type="pick")
    assert died.rerun_on_resume and not raised.rerun_on_resume and not kept.rerun_on_resume
    summary = summarize([kept, died, raised], benchmark={"name": "b"}, policy={"name": "p"})
    s = summary.document()
    assert s["n_success"] == 1 and s["n_errors"] == 2
    assert [e["error_kind"] for e in s["errors"]] == ["infrastructure", "episode"]
    assert s["output_errors"] == [{"episode_index": 0, "errors": kept.output_errors}]
    lines = summary_lines(summary)
    assert any(ln.startswith("  1 of the errors are infrastructure failures") and "resume=true" in ln for ln in lines)
    assert "  outputs not written for 1 episode, outcomes kept (episode 0: GlanceRecorder: OSError: [Errno 28] No " \
           "space left on device; all in results.json output_errors)" in lines
    assert EpisodeResult.from_dict(died.to_dict()) == died


def test_parity_notes_are_listed_and_counted():
    """An episode the other task_rules would judge otherwise keeps its score and is listed, in results.json
    and in the summary."""
    from molmo_lerobot.results import summary_lines

    note = "open: zero-range joint 'knob' at 0 comes first (MolmoSpaces' fraction is NaN); task_rules=fixed ..."
    noted = EpisodeResult(0, 1, "a.Open", False, False, 10, 1, task_type="open", extra={"parity_notes": [note]})
    plain = EpisodeResult(1, 1, "a.Open", True, True, 10, 2, task_type="open")
    summary = summarize([noted, plain], benchmark={"name": "b"}, policy={"name": "p"})
    s = summary.document()
    assert s["n_success"] == 1 and s["parity_notes"] == [{"episode_index": 0, "notes": [note]}]
    assert f"  1 episode judged otherwise by the other task_rules (episode 0: {note}; all in results.json " \
           "parity_notes)" in summary_lines(summary)


def test_the_report_lists_parity_notes():
    from molmo_lerobot.export.report import render_report

    note = "open: zero-range joint 'knob' at 0 comes first (MolmoSpaces' fraction is NaN)"
    results = [EpisodeResult(0, 1, "a.Open", False, False, 10, 1, task_type="open", extra={"parity_notes": [note]}),
               EpisodeResult(1, 1, "a.Open", True, True, 10, 2, task_type="open")]
    page = render_report(summarize(results, benchmark={"name": "b"}, policy={"name": "p"}), results, {}, None)
    assert "1 episode judged otherwise by the other <code>task_rules</code>" in page and "zero-range joint" in page
    plain = render_report(summarize(results[1:], benchmark={"name": "b"}, policy={"name": "p"}), results[1:], {}, None)
    assert "judged otherwise" not in plain
