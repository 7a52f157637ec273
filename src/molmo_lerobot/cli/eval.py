"""``molmo-eval policy=P benchmark=B workers=N [key=value ...]``: evaluate a policy.

A Hydra app (``@hydra.main``) over ``conf/eval.yaml`` (plus the config dirs plugins add): ``-m`` sweeps
(``molmo-eval -m policy=random,scripted limit=2`` writes one complete run per job under
``hydra.sweep.dir/hydra.sweep.subdir``), ``--cfg job|hydra|all``, ``--help``, ``--info``.
Each job validates its config (:class:`~molmo_lerobot.run_config.RunConfig`) before any
work. Bad overrides, config and run errors print one ``molmo-eval: error:`` message and exit 2.
"""

from __future__ import annotations

import os
import sys
from typing import Any

from molmo_lerobot.gl import use_headless_gl
from molmo_lerobot.runner.progress import quiet_library_bars

_CFG_TYPES = ("job", "hydra", "all")


def main(argv: list[str] | None = None) -> int:
    from molmo_lerobot.runner.supervisor import reaping_children

    with reaping_children():  # exit only after every child process is reaped
        return _main(argv)


def _main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    for i, a in enumerate(args):  # `--cfg` alone (our older form) means Hydra's `--cfg job`
        if a in ("--cfg", "-c") and (i + 1 == len(args) or args[i + 1] not in _CFG_TYPES):
            args.insert(i + 1, "job")
            break
    use_headless_gl()
    quiet_library_bars()  # not on a terminal: LeRobot's merge bars would fill the log with redraws
    import hydra
    from hydra.core.global_hydra import GlobalHydra
    from hydra.errors import HydraException, OverrideParseException
    from omegaconf.errors import OmegaConfBaseException

    from molmo_lerobot.config import config_message, primary_config_dir
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.runner.supervisor import RunInterrupted

    codes: list[int] = []
    jobs: list[dict[str, Any]] = []  # one row per job, for a sweep's closing table
    app = hydra.main(version_base="1.3", config_path=str(primary_config_dir()), config_name="eval")(
        lambda cfg: codes.append(_job(cfg, jobs)))
    saved_argv, saved_full_error = sys.argv, os.environ.get("HYDRA_FULL_ERROR")
    sys.argv = ["molmo-eval", *args]  # hydra.main parses sys.argv
    os.environ["HYDRA_FULL_ERROR"] = "1"  # Hydra raises its errors to us instead of printing them and exiting 1
    try:
        app()
    except SystemExit as exc:  # --help, --hydra-help; a bad flag (argparse's usage message)
        return 0 if exc.code is None else exc.code if isinstance(exc.code, int) else 1
    except OverrideParseException as exc:
        print(f"molmo-eval: error: {_override_message(exc.override, exc.message)}", file=sys.stderr)
        return 2
    except (HydraException, OmegaConfBaseException, PluginError) as exc:
        print(f"molmo-eval: error: {config_message(exc)}", file=sys.stderr)
        return 2
    except RunInterrupted as exc:  # stops a sweep too
        print(f"molmo-eval: {exc}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print("molmo-eval: interrupted; finished episodes are kept in episodes.jsonl "
              "(rerun with resume=true to continue)", file=sys.stderr)
        return 130
    finally:
        sys.argv = saved_argv
        if saved_full_error is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = saved_full_error
        GlobalHydra.instance().clear()
    if len(jobs) > 1 or any(a in ("-m", "--multirun") for a in args):
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


def _override_message(override: str, message: str) -> str:
    """One line for an override Hydra's grammar cannot parse; says how to quote a value that needs it."""
    lines = [line for line in message.splitlines() if not line.startswith("See https://")]
    detail = lines[0].split(": ", 1)[-1] if lines else "syntax error"
    if len(lines) > 1 and lines[0].startswith("LexerNoViableAltException"):  # Hydra points at the character
        at = len(lines[1]) - len(lines[1].lstrip()) - lines[0].rfind(override)
        detail = f"{override[at]!r} is not allowed there" if 0 <= at < len(override) else "a character is not allowed"
        key, sep, value = override.partition("=")
        if sep and len(key) < at < len(override) and not {"'", '"'} & set(value):
            return (f"cannot parse override {override!r}: {override[at]!r} is allowed only in a quoted value; "
                    f"quote it, e.g. molmo-eval '{key}=\"{value}\"'")
    return f"cannot parse override {override!r}: {detail} (grammar: https://hydra.cc/docs/advanced/override_grammar/basic)"


def _job(cfg: Any, jobs: list[dict[str, Any]]) -> int:
    """One run, validated here (a sweep job writes to its sweep subdir unless ``output_dir`` is set);
    appends its row to ``jobs``."""
    row: dict[str, Any] = {"job": len(jobs), "policy": str(cfg.get("policy", {}).get("name", "?")),
                           "benchmark": str(cfg.get("benchmark", {}).get("path")
                                            or cfg.get("benchmark", {}).get("name", "?")),
                           "success": "error", "exit": 2, "outputs": "-"}
    jobs.append(row)
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    from molmo_lerobot.config import ConfigError
    from molmo_lerobot.errors import RunError
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.results import summary_lines
    from molmo_lerobot.run_config import RunConfig, RunConfigError
    from molmo_lerobot.runner.evaluate import run_evaluation
    from molmo_lerobot.runner.supervisor import WorkerStartError

    expected: tuple[type[BaseException], ...] = (ConfigError, PluginError, RunError, WorkerStartError,
                                                 RunConfigError)
    try:
        from molmo_lerobot.benchmark.load import BenchmarkError

        expected += (BenchmarkError,)
        if HydraConfig.get().mode == RunMode.MULTIRUN and cfg.get("output_dir") is None:
            cfg.output_dir = HydraConfig.get().runtime.output_dir
        res = run_evaluation(RunConfig.of(cfg))
    except expected as exc:
        for line in str(exc).splitlines() or [type(exc).__name__]:  # one line per problem
            print(f"molmo-eval: error: {line}", file=sys.stderr)
        row["success"] = f"error: {(str(exc).splitlines() or [type(exc).__name__])[0][:60]}"
        return 2
    s = res.summary
    row["outputs"] = str(res.output_dir)
    row["success"] = ("no episode ran" if s["success_rate"] is None else
                      f"{s['success_rate']:.3f} ({s['n_success']}/{s['n_episodes']})"
                      + (f", {s['n_errors']} errored" if s["n_errors"] else ""))
    print("\n".join([*summary_lines(res.run_summary), f"outputs: {res.output_dir}"]))
    push = res.summary.get("push")
    if push and not push["ok"]:
        print(f"molmo-eval: error: push to the Hub as {push['repo_id']} failed ({push['error']}); every local "
              f"file is kept in {res.output_dir} (results.json records the failure)", file=sys.stderr)
        row["exit"] = 1
    else:
        row["exit"] = 0 if s["success_rate"] is not None else 1  # 1: no episode ran, so there is no score
    return row["exit"]


if __name__ == "__main__":
    raise SystemExit(main())
