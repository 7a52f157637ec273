"""``molmo-eval policy=P benchmark=B workers=N [key=value ...]``: evaluate a policy.

A Hydra app (``@hydra.main``) over ``conf/eval.yaml`` (plus the config dirs plugins add): ``-m`` sweeps
(``molmo-eval -m policy=random,scripted limit=2`` writes one complete run per job under
``hydra.sweep.dir/hydra.sweep.subdir``; their workers fork from one fork server where the jobs
preload the same modules), ``--cfg job|hydra|all``, ``--help``, ``--info``.
Each job validates its config (:class:`~molmo_lerobot.run_config.RunConfig`) before any
work. Bad overrides, config and run errors print one ``molmo-eval: error:`` message and exit 2.
With ``resume=true`` the options the command line gives (:func:`~molmo_lerobot.config.given_keys`)
are all it changes: the others are the run's (``output_dir=X resume=true`` is the whole command).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from molmo_lerobot.errors import MolmoError
from molmo_lerobot.gl import use_headless_gl
from molmo_lerobot.runner.progress import quiet_library_bars

if TYPE_CHECKING:
    from molmo_lerobot.runner.forkserver import ForkServerPool

_CFG_TYPES = ("job", "hydra", "all")


def main() -> int:
    """The ``molmo-eval`` console script: the one caller of ``hydra.main``, which reads ``sys.argv``.
    In-process callers compose instead (:func:`molmo_lerobot.config.compose`, ``RunConfig.of``,
    :func:`~molmo_lerobot.runner.evaluate.run_evaluation`)."""
    from molmo_lerobot.runner.supervisor import reaping_children

    _cfg_alone_means_job(sys.argv)
    _resume_in_the_runs_groups(sys.argv)
    with reaping_children():  # exit only after every child process is reaped
        try:
            return _main(multirun=any(a in ("-m", "--multirun") for a in sys.argv[1:]))
        except KeyboardInterrupt:  # outside the supervisor, whose stop names the run directory (RunInterrupted)
            print("molmo-eval: interrupted while no episode was running (setting the run up or finishing it); "
                  "where it had written a run directory, output_dir=<it> resume=true continues the run",
                  file=sys.stderr)
            return 130


def _cfg_alone_means_job(argv: list[str]) -> None:
    """``--cfg`` alone (our older form) is Hydra's ``--cfg job``: the one word is added to this
    process's own command line, before Hydra reads it."""
    for i, a in enumerate(argv[1:], start=1):
        if a in ("--cfg", "-c") and (i + 1 == len(argv) or argv[i + 1] not in _CFG_TYPES):
            argv.insert(i + 1, "job")
            return


def _resume_in_the_runs_groups(argv: list[str]) -> None:
    """``output_dir=X resume=true`` (or ``dataset_id=D resume=true``) composes in the run's config groups:
    the run's ``benchmark=`` and ``policy=`` choices (from its ``run.json``) are added to this process's
    command line where it names none, so that an option of the run's groups given with it
    (``benchmark.image_size=128`` on a PushT run) reaches the resume's check, which refuses it naming it,
    instead of Hydra's "no such key" against the default groups. A run that cannot be found or read is
    left to the run to report."""
    args = [a for a in argv[1:] if not a.startswith("-")]
    values = dict(a.split("=", 1) for a in args if "=" in a)
    if values.get("resume", "").lower() != "true" or not (values.get("output_dir") or values.get("dataset_id")):
        return
    import json
    from pathlib import Path

    from molmo_lerobot.errors import MolmoError
    from molmo_lerobot.namespaces import DatasetStore
    from molmo_lerobot.runner.run_directory import RUN_FILE

    try:
        run_dir = (Path(values["output_dir"]).expanduser() if values.get("output_dir")
                   else DatasetStore().run_dir(values["dataset_id"]))
        options = json.loads((run_dir / RUN_FILE).read_text()).get("options", {})
    except (OSError, ValueError, AttributeError, MolmoError):
        return
    for group in ("benchmark", "policy"):
        name = options.get(group, {}).get("name") if isinstance(options.get(group), dict) else None
        if isinstance(name, str) and group not in values and not options[group].get("path"):
            argv.insert(1, f"{group}={name}")


def _main(multirun: bool) -> int:
    use_headless_gl()
    quiet_library_bars()  # not on a terminal: LeRobot's merge bars would fill the log with redraws
    import hydra
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from molmo_lerobot.config import config_message, primary_config_dir
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.runner.forkserver import ForkServerPool
    from molmo_lerobot.runner.supervisor import RunInterrupted

    codes: list[int] = []
    jobs: list[dict[str, Any]] = []  # one row per job, for a sweep's closing table
    fork_servers = ForkServerPool()  # a sweep's jobs fork their workers from one server where they can
    app = hydra.main(version_base="1.3", config_path=str(primary_config_dir()), config_name="eval")(
        lambda cfg: codes.append(_job(cfg, jobs, fork_servers)))
    os.environ["HYDRA_FULL_ERROR"] = "1"  # Hydra raises its errors to us instead of printing them and exiting 1
    try:
        with fork_servers:
            app()
    except SystemExit as exc:  # --help, --hydra-help; a bad flag (argparse's usage message)
        return 0 if exc.code is None else exc.code if isinstance(exc.code, int) else 1
    except (HydraException, OmegaConfBaseException, PluginError) as exc:
        print(f"molmo-eval: error: {config_message(exc)}", file=sys.stderr)
        return 2
    except RunInterrupted as exc:  # stops a sweep too
        print(f"molmo-eval: {exc}", file=sys.stderr)
        return 128 + exc.signum
    if len(jobs) > 1 or multirun:
        print("\n".join(sweep_table(jobs)))
    return max(codes, default=0)


def sweep_table(jobs: list[dict[str, Any]]) -> list[str]:
    """A sweep's jobs in one table: job, policy, benchmark, score (or the error), exit status, outputs."""
    rows = [("job", "policy", "benchmark", "success", "exit", "outputs")]
    for job in jobs:
        rows.append((str(job["job"]), job["policy"], job["benchmark"], job["success"], str(job["exit"]),
                     job["outputs"]))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]) - 1)]
    lines = [f"sweep: {len(jobs)} job{'s' * (len(jobs) != 1)}"]
    lines += ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=False)) + "  " + r[-1] for r in rows]
    return lines


def refused_errors() -> tuple[type[MolmoError], ...]:
    """The errors ``molmo-eval`` refuses a run with: one ``molmo-eval: error:`` line per line of the
    message (one problem each), exit status 2."""
    from molmo_lerobot.benchmark.load import BenchmarkError
    from molmo_lerobot.config import ConfigError
    from molmo_lerobot.errors import RunError
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.run_config import RunConfigError
    from molmo_lerobot.runner.supervisor import WorkerStartError

    return ConfigError, PluginError, RunError, WorkerStartError, RunConfigError, BenchmarkError


def exit_status(summary: Mapping[str, Any]) -> int:
    """A finished run's exit status: 0, or 1 where it has no score (no episode ran) or its push to
    the Hub failed."""
    push = summary.get("push")
    return 1 if summary["success_rate"] is None or (push and not push["ok"]) else 0


def _job(cfg: Any, jobs: list[dict[str, Any]], fork_servers: ForkServerPool) -> int:
    """One run, validated here (a sweep job writes to its sweep subdir unless ``output_dir`` is set),
    its workers' fork server borrowed from ``fork_servers``; appends its row to ``jobs``."""
    row: dict[str, Any] = {"job": len(jobs), "policy": str(cfg.get("policy", {}).get("name", "?")),
                           "benchmark": str(cfg.get("benchmark", {}).get("path")
                                            or cfg.get("benchmark", {}).get("name", "?")),
                           "success": "error", "exit": 2, "outputs": "-"}
    jobs.append(row)
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    from molmo_lerobot.config import given_keys
    from molmo_lerobot.results import summary_lines
    from molmo_lerobot.run_config import RunConfig
    from molmo_lerobot.runner.evaluate import run_evaluation

    try:
        given = given_keys(list(HydraConfig.get().overrides.task))  # a resume takes the others from the run
        if HydraConfig.get().mode == RunMode.MULTIRUN and cfg.get("output_dir") is None:
            cfg.output_dir = HydraConfig.get().runtime.output_dir
            given.add("output_dir")
        res = run_evaluation(RunConfig.of(cfg), fork_servers, given)
    except refused_errors() as exc:
        for line in str(exc).splitlines() or [type(exc).__name__]:  # one line per problem
            print(f"molmo-eval: error: {line}", file=sys.stderr)
        row["success"] = f"error: {(str(exc).splitlines() or [type(exc).__name__])[0][:60]}"
        return 2
    s = res.summary
    row["outputs"] = str(res.output_dir)
    row["success"] = ("no episode ran" if s["success_rate"] is None else
                      f"{s['success_rate']:.3f} ({s['n_success']}/{s['n_episodes']})"
                      + (f", {s['n_errors']} errored" if s["n_errors"] else ""))
    print("\n".join([*summary_lines(res.run_summary), f"outputs: {res.output_dir}", *_stored_lines(s)]))
    push = s.get("push")
    if push and not push["ok"]:
        print(f"molmo-eval: error: push to the Hub as {push['repo_id']} failed ({push['error']}); every local "
              f"file is kept in {res.output_dir} (results.json records the failure)", file=sys.stderr)
    row["exit"] = exit_status(s)
    return row["exit"]


def _stored_lines(summary: Mapping[str, Any]) -> list[str]:
    """Where a ``dataset_id=`` run's recording went in the dataset store (a run reaching its summary stored it)."""
    dataset_id = (summary.get("config") or {}).get("dataset_id")
    if not dataset_id:
        return []
    from molmo_lerobot.namespaces import DatasetStore

    return [f"stored: {DatasetStore().path(dataset_id)} (dataset_id={dataset_id}; molmo-datasets show {dataset_id})"]


if __name__ == "__main__":
    raise SystemExit(main())
