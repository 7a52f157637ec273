"""Weights & Biases logging of a finished run, behind ``wandb.enable=true`` (off by default).

Logs the run config, the overall and per-task scores (summary metrics), a per-episode
table and ``results.json`` / ``report.html`` as files. Credentials and mode come from
wandb's own environment (``WANDB_API_KEY``, ``WANDB_MODE=offline`` …). A logging failure
is a warning; it never fails the run.
"""

from __future__ import annotations

import logging
from pathlib import Path

from molmo_lerobot import fileio
from molmo_lerobot.results import RESULTS_FILE, EpisodeResult, Rates, RunSummary

log = logging.getLogger(__name__)

EPISODE_COLUMNS = ["episode_index", "house_index", "task", "prompt", "success", "success_once", "steps",
                   "seed", "duration_s", "error"]


def metrics(summary: RunSummary) -> dict[str, float]:
    """Flat scalar metrics: overall and ``<task>/<metric>`` for every task."""
    keys = ("success_rate", "success_once_rate", "n_episodes", "n_success", "n_errors", "avg_sum_reward",
            "avg_max_reward")

    def scalars(block: Rates) -> dict[str, float]:  # null rates: no episode simulated
        return {k: v for k in keys if (v := getattr(block, k)) is not None}

    out = scalars(summary)
    if summary.ci95 is not None:
        out.update({"ci95_lo": summary.ci95[0], "ci95_hi": summary.ci95[1]})
    for task, block in summary.per_task.items():
        out.update({f"{task}/{k}": v for k, v in scalars(block).items()})
    return out


def log_run(output_dir: Path | str, summary: RunSummary, results: list[EpisodeResult]) -> bool:
    """Log the run to W&B if ``summary.config["wandb"]["enable"]``; returns whether it was logged."""
    settings = ((summary.config or {}).get("wandb") or {})
    if not settings.get("enable"):
        return False
    output_dir = Path(output_dir)
    try:
        import wandb

        fileio.make_dirs(output_dir / "wandb", root=output_dir)  # W&B writes its own files in there
        bench = summary.benchmark.name if summary.benchmark else "benchmark"
        policy = (summary.policy or {}).get("name", "policy")
        run = wandb.init(project=settings.get("project") or "molmo-eval", entity=settings.get("entity"),
                         name=f"{bench}-{policy}-{output_dir.name}", job_type="eval", dir=str(output_dir),
                         config=summary.config or {}, tags=[str(bench), str(policy)])
        try:
            table = wandb.Table(columns=EPISODE_COLUMNS, data=[
                [r.episode_index, r.house_index, r.task_type or r.task_cls, r.prompt, r.success, r.success_once,
                 r.steps, r.seed, round(r.duration_s, 3), r.error] for r in results])
            run.log({"episodes": table, **metrics(summary)})
            run.summary.update(metrics(summary))
            for name in (RESULTS_FILE, "report.html"):
                if (output_dir / name).is_file():
                    run.save(str(output_dir / name), base_path=str(output_dir), policy="now")
        finally:
            run.finish()
    except Exception as exc:
        log.warning("W&B logging failed (the run's results are unaffected): %s: %s", type(exc).__name__,
                    str(exc).splitlines()[0] if str(exc) else "")
        return False
    return True
