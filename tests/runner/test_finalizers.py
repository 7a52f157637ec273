"""Run finalizers: chosen from the config, run after the score, what they add returned, failures collected
as one line each."""

from __future__ import annotations

from molmo_lerobot.results import Push, summarize
from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.finalizers import finalize_run, run_finalizers


def test_the_config_chooses_the_finalizers():
    assert [f.label for f in run_finalizers(RunConfig())] == ["eval_info.json", "report"]
    assert [f.label for f in run_finalizers(RunConfig.of({"wandb": {"enable": True}}))] == [
        "eval_info.json", "report", "W&B log"]


def test_every_step_runs_and_each_failure_is_one_line(tmp_path):
    ran = []

    class Recorded:
        def finalize(self, output_dir, results, summary):
            ran.append("recorder")
            raise OSError("disk full\nsecond line")

    class Last:
        label = "last"

        def finalize(self, output_dir, results, summary):
            ran.append("last")

    scored = summarize([], seed=0)
    final = finalize_run(tmp_path, [], scored, [Recorded()], [Last()])
    assert ran == ["recorder", "last"]
    assert final.export_errors == ["export Recorded: OSError: disk full"]
    assert final.document() == {**scored.document(), "export_errors": ["export Recorded: OSError: disk full"]}


def test_what_a_step_returns_goes_into_the_summary_the_next_steps_see(tmp_path):
    seen = []

    class Pushes:
        def finalize(self, output_dir, results, summary):
            return Push(repo_id="ns/name", ok=False, error="HTTP 500")

    class Report:
        label = "report"

        def finalize(self, output_dir, results, summary):
            seen.append(summary.push)

    scored = summarize([], seed=0)
    final = finalize_run(tmp_path, [], scored, [Pushes()], [Report()])
    assert seen == [Push(repo_id="ns/name", ok=False, error="HTTP 500")] and final.export_errors is None
    assert final.document()["push"] == {"repo_id": "ns/name", "ok": False, "error": "HTTP 500"}
    assert "push" not in scored.document()  # the scored summary is never edited
