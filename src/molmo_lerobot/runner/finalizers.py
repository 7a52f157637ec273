"""What runs once a run is scored (``results.json`` written), in order: every recorder factory's
``finalize`` (the dataset, the Hub push), then the run's finalizers chosen from its config:
``eval_info.json`` and the report (every run), and the W&B log (``wandb.enable=true``).

A finalizer is an object with a ``label`` and ``finalize(output_dir, results, summary)``, the
recorder factories' own run-level step. It returns what it adds to ``results.json`` (a
:data:`~molmo_lerobot.results.SummaryPiece`, e.g. the dataset's ``push``) or ``None``; the steps
after it see the summary with it. One that fails never changes the score: its one-line failure
goes to ``results.json`` (``export_errors``) and the run then fails with it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from molmo_lerobot.results import EpisodeResult, RunSummary, SummaryPiece

if TYPE_CHECKING:
    from molmo_lerobot.run_config import RunConfig


class Finalizer(Protocol):
    label: str

    def finalize(self, output_dir: Path, results: list[EpisodeResult],
                 summary: RunSummary) -> SummaryPiece | None: ...


class EvalInfoFinalizer:
    """``eval_info.json``: the score in ``lerobot-eval``'s schema."""

    label = "eval_info.json"

    def finalize(self, output_dir: Path, results: list[EpisodeResult], summary: RunSummary) -> None:
        from molmo_lerobot.export.eval_info import write_eval_info

        write_eval_info(output_dir, summary, results)


class ReportFinalizer:
    """``report.html``."""

    label = "report"

    def finalize(self, output_dir: Path, results: list[EpisodeResult], summary: RunSummary) -> None:
        from molmo_lerobot.export.report import write_report

        write_report(output_dir, summary, results)


class WandbFinalizer:
    """The run logged to Weights & Biases (after the report, which it uploads)."""

    label = "W&B log"

    def finalize(self, output_dir: Path, results: list[EpisodeResult], summary: RunSummary) -> None:
        from molmo_lerobot.export.wandb_log import log_run

        log_run(output_dir, summary, results)


def run_finalizers(config: RunConfig) -> list[Finalizer]:
    """The finalizers ``config`` asks for, in the order they run."""
    return [EvalInfoFinalizer(), ReportFinalizer(), *([WandbFinalizer()] if config.wandb.enable else [])]


def finalize_run(output_dir: Path, results: list[EpisodeResult], summary: RunSummary, recorders: list[Any],
                 finalizers: list[Finalizer]) -> RunSummary:
    """Run the recorder factories' ``finalize`` and then ``finalizers``; the summary with what they
    added and, if any failed, ``export_errors`` (one line per failure)."""
    steps = [*((f"export {type(f).__name__}", f) for f in recorders), *((f.label, f) for f in finalizers)]
    failed = []
    for label, step in steps:
        try:
            piece = step.finalize(output_dir, results, summary)
        except Exception as exc:
            failed.append(f"{label}: {type(exc).__name__}: {exc}".splitlines()[0])
            continue
        if piece is not None:
            summary = summary.with_piece(piece)
    return summary.model_copy(update={"export_errors": failed}) if failed else summary
