"""Run finalizers: chosen from the config, run after the score, failures collected as one line each."""

from __future__ import annotations

from molmo_lerobot.run_config import RunConfig
from molmo_lerobot.runner.finalizers import finalize_run, run_finalizers


def test_the_config_chooses_the_finalizers():
    assert [f.label for f in run_finalizers(RunConfig())] == ["report"]
    assert [f.label for f in run_finalizers(RunConfig.of({"wandb": {"enable": True}}))] == ["report", "W&B log"]


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

    failed = finalize_run(tmp_path, [], {}, [Recorded()], [Last()])
    assert ran == ["recorder", "last"]
    assert failed == ["export Recorded: OSError: disk full"]
