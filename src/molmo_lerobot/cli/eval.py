"""``molmo-eval policy=P benchmark=B workers=N [key=value ...]``: evaluate a policy.

A Hydra app over ``conf/eval.yaml`` (plus the config dirs plugins add): ``-m`` sweeps
(``molmo-eval -m policy=random,scripted limit=2`` writes one complete run per job under
``hydra.sweep.dir/hydra.sweep.subdir``), ``--cfg job|hydra|all``, ``--help``, ``--info``.
Bad overrides and run errors print one ``molmo-eval: error:`` message and exit 2.
"""

from __future__ import annotations

import os
import sys
from typing import Any

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
    os.environ.setdefault("MUJOCO_GL", "egl")
    from hydra import version
    from hydra._internal.hydra import Hydra
    from hydra._internal.utils import create_config_search_path, get_args_parser
    from hydra.core.global_hydra import GlobalHydra
    from hydra.errors import HydraException, OverrideParseException
    from omegaconf.errors import OmegaConfBaseException

    from molmo_lerobot.config import config_message, primary_config_dir
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.runner.supervisor import RunInterrupted

    parser = get_args_parser()
    parser.prog = "molmo-eval"
    ns = parser.parse_args(args)
    version.setbase("1.3")
    codes: list[int] = []
    GlobalHydra.instance().clear()
    try:
        search_path = create_config_search_path(f"file://{primary_config_dir()}")
        hydra = Hydra.create_main_hydra2(task_name="molmo_eval", config_search_path=search_path)
        if ns.help:
            hydra.app_help(config_name="eval", args_parser=parser, args=ns)
        elif ns.hydra_help:
            hydra.hydra_help(config_name="eval", args_parser=parser, args=ns)
        elif ns.cfg:
            hydra.show_cfg(config_name="eval", overrides=ns.overrides, cfg_type=ns.cfg, package=ns.package,
                           resolve=ns.resolve)
        elif ns.shell_completion:
            hydra.shell_completion(config_name="eval", overrides=ns.overrides)
        elif ns.info:
            hydra.show_info(ns.info, config_name="eval", overrides=ns.overrides)
        elif ns.multirun:
            hydra.multirun(config_name="eval", task_function=lambda cfg: codes.append(_job(cfg, sweep=True)),
                           overrides=[*ns.overrides, "hydra.mode=MULTIRUN"])
        else:
            hydra.run(config_name="eval", task_function=lambda cfg: codes.append(_job(cfg, sweep=False)),
                      overrides=[*ns.overrides, "hydra.mode=RUN"])
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
        GlobalHydra.instance().clear()
    return max(codes, default=0)


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


def _job(cfg: Any, *, sweep: bool) -> int:
    """One run (a sweep job writes to its sweep subdir unless ``output_dir`` is set)."""
    from hydra.core.hydra_config import HydraConfig

    from molmo_lerobot.config import ConfigError
    from molmo_lerobot.plugins import PluginError
    from molmo_lerobot.runner.evaluate import RunError, run_evaluation
    from molmo_lerobot.runner.results import summary_lines
    from molmo_lerobot.runner.run_config import RunConfigError
    from molmo_lerobot.runner.supervisor import WorkerStartError

    expected: tuple[type[BaseException], ...] = (ConfigError, PluginError, RunError, WorkerStartError,
                                                 RunConfigError)
    try:
        from molmo_lerobot.benchmark.load import BenchmarkError

        expected += (BenchmarkError,)
        if sweep and cfg.get("output_dir") is None:
            cfg.output_dir = HydraConfig.get().runtime.output_dir
        res = run_evaluation(cfg)
    except expected as exc:
        for line in str(exc).splitlines() or [type(exc).__name__]:  # one line per problem
            print(f"molmo-eval: error: {line}", file=sys.stderr)
        return 2
    print("\n".join([*summary_lines(res.summary), f"outputs: {res.output_dir}"]))
    push = res.summary.get("push")
    if push and not push["ok"]:
        print(f"molmo-eval: error: push to the Hub as {push['repo_id']} failed ({push['error']}); every local "
              f"file is kept in {res.output_dir} (results.json records the failure)", file=sys.stderr)
        return 1
    return 0 if res.summary["success_rate"] is not None else 1  # 1: no episode ran, so there is no score


if __name__ == "__main__":
    raise SystemExit(main())
