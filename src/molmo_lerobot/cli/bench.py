"""``molmo-bench``: check benchmark files and make new benchmarks.

  molmo-bench list
  molmo-bench validate BENCHMARK [KEY=VALUE ...]
  molmo-bench generate [GENERATOR] --task pick --houses 10 --episodes-per-house 5 --seed 0 --name pick_v1 [--out DIR]

``list`` prints every benchmark ``molmo-eval benchmark=<name>`` runs: the registered benchmark directories (their
episodes, and the plugin that ships them) and the env-suite benchmarks (``libero_object`` …, ``pusht``: their
suite, how their episodes are counted, LeRobot's step limit, and the version and licence of the distributions
their env and assets come from).
``validate`` takes what ``molmo-eval`` and the Gymnasium env take: a shipped benchmark's name
(``pick_v2``) or a benchmark directory or JSON file (a relative path from the current directory).
It prints a summary (name, episodes, tasks, content hash) and exits 0 for a valid
file — one MolmoSpaces accepts — printing one ``warning:`` line per thing this machine lacks
to run it (scene assets, robot, camera system) with how to get it; an invalid file gets every
problem (file, episode index, field) and, like ``molmo-eval`` refusing it, exit 2.
``KEY=VALUE`` are run-config overrides saying where data lives (``molmospaces.assets_dir=…``,
``scene_xml_paths=[…]``, ``+asset_libraries.x=…``).
An env-suite benchmark's name validates the episode plan ``molmo-eval benchmark=<name>`` would run with the
same overrides (``seed=``, ``horizon=``, ``benchmark.episodes_per_task=`` …): its options, then its episodes
against the task catalogue the suite's own env lists (LIBERO: started in the LIBERO venv; ``--schema-only``
checks the options alone).
``generate`` writes a deterministic benchmark (``benchmark.json`` + ``benchmark_metadata.json``)
with one of :data:`GENERATORS` (default ``v1``) and validates it; the output directory appears only
once it is complete. Each shipped benchmark is what its generator writes for the arguments its
``benchmark_metadata.json`` records (``generator``), byte for byte; the ``*_v3`` benchmarks are the
``*_v2`` episodes with render profile v3 named in their metadata.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import re
import shutil
import sys
import tempfile
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from molmo_lerobot.benchmark.load import Benchmark, BenchmarkError, Problem, load_benchmark, validation_messages
from molmo_lerobot.benchmark.molmospaces import known_task_name
from molmo_lerobot.benchmark.schema import NATIVE_TASK_CLS
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.plugins import PluginConflict, Plugins
from molmo_lerobot.suites.benchmark import suite_benchmarks

#: the exit status for a benchmark that cannot be run (``molmo-eval`` refuses it with the same)
INVALID = 2


@dataclass(frozen=True)
class Generator:
    """One ``molmo-bench generate <name>``: the module whose ``generate_benchmark`` makes the episodes."""

    module: str
    tasks: tuple[str, ...]  # the --task values; the first is the default
    about: str
    #: ``generate_benchmark(task, houses, episodes_per_house, seed, name)``; ``False``: one task, no task argument
    takes_task: bool = True

    def generate(self, task: str | None, houses: int, per_house: int, seed: int,
                 name: str) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        task = task or self.tasks[0]
        make = importlib.import_module(self.module).generate_benchmark
        if self.takes_task:
            return make(task, houses, per_house, seed, name)
        if task not in self.tasks:
            raise ValueError(f"generate: this generator makes {self.tasks[0]!r} episodes only, not --task {task!r}")
        return make(houses, per_house, seed, name)


#: every generator ``molmo-bench generate`` runs (the shipped benchmarks name theirs in their metadata)
GENERATORS = {
    "v1": Generator("molmo_lerobot.content.tabletop.generate",
                    ("pick", "pick_and_place", "pick_and_place_next_to", "pick_and_place_color", "open", "close"),
                    "the procedural (and articulated) tabletop, Franka Panda, exocentric + wrist camera"),
    "v2": Generator("molmo_lerobot.content.libero.generate",
                    ("pick", "pick_and_place", "next_to", "color", "open", "close"),
                    "textured LIBERO rooms (and LIBERO cabinets), franka_droid, DROID cameras"),
    "nav": Generator("molmo_lerobot.content.libero.generate_nav", ("nav_to_obj",),
                     "nav_to_obj in multi-room nav_houses, mobile_franka", takes_task=False),
    "door": Generator("molmo_lerobot.content.doors.generate", ("door_opening",),
                      "open the door between two door_rooms rooms, mobile_franka", takes_task=False),
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="molmo-bench", description="Check and make benchmarks.")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="every benchmark molmo-eval runs: registered directories and env suites")
    val = sub.add_parser("validate", help="check a benchmark: a shipped name, a directory or a JSON file")
    val.add_argument("path", metavar="BENCHMARK", help="a shipped benchmark's name (pick_v2) or a path")
    val.add_argument("--schema-only", action="store_true", help="skip the checks against installed plugins")
    val.add_argument("overrides", nargs="*", metavar="KEY=VALUE",
                     help="run-config overrides that locate data (molmospaces.assets_dir=…, scene_xml_paths=[…], …)")
    gen = sub.add_parser("generate", help="generate a benchmark deterministically",
                         epilog="generators: " + "; ".join(f"{n}: {g.about} (--task {', '.join(g.tasks)})"
                                                            for n, g in GENERATORS.items()))
    gen.add_argument("generator", nargs="?", default="v1", choices=list(GENERATORS),
                     help="which generator (default v1)")
    gen.add_argument("--task", help="what the episodes ask (default: the generator's first task)")
    gen.add_argument("--houses", type=int, required=True, help="number of scenes (houses)")
    gen.add_argument("--episodes-per-house", type=int, required=True)
    gen.add_argument("--seed", type=int, default=0)
    gen.add_argument("--name", required=True)
    gen.add_argument("--out", type=Path, help="output directory (default: benchmarks/<name>)")
    gen.add_argument("--force", action="store_true", help="replace an existing output directory")
    args = parser.parse_args(argv)
    if args.command == "list":
        return _list()
    if args.command == "validate":
        if args.path in suite_benchmarks() and not Path(args.path).exists():
            return _validate_suite(args.path, schema_only=args.schema_only, overrides=args.overrides)
        return _validate(args.path, schema_only=args.schema_only, overrides=args.overrides)
    return _generate(args)


def _list() -> int:
    """One line per benchmark (name, kind, episodes, horizon, directory), then each env suite's sources."""
    from omegaconf import OmegaConf

    from molmo_lerobot.benchmark.registry import benchmark_dir, benchmark_names
    from molmo_lerobot.paths import data_path
    from molmo_lerobot.suites.benchmark import SUITES

    plugins = Plugins()
    rows = [("benchmark", "kind", "episodes", "horizon", "where")]
    for name in benchmark_names(plugins):
        try:
            path = benchmark_dir(name, plugins)
        except PluginConflict as exc:
            rows.append((name, "directory", "?", "?", str(exc)))
            continue
        meta_file = path / "benchmark_metadata.json"
        meta = json.loads(meta_file.read_text()) if meta_file.is_file() else {}
        rows.append((name, "directory", str(meta.get("num_episodes", "?")), "per episode", str(path)))
    sources = []
    for kind_name, kind in SUITES.items():
        for name, steps in kind.benchmarks.items():
            conf = data_path("conf") / "benchmark" / f"{name}.yaml"
            per_task = OmegaConf.select(OmegaConf.load(conf), "episodes_per_task") if conf.is_file() else None
            per_task = per_task or kind.options["episodes_per_task"]
            rows.append((name, f"env suite {kind_name}", f"{per_task} per task", f"{steps} (LeRobot's)", str(conf)))
        sources.append(f"env suite {kind_name}: " + ", ".join(_distribution(d, kind.venv) for d in kind.distributions))
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row[:4], widths, strict=True)) + "  " + row[4])
    print()
    print("\n".join(sources))
    return 0


def _distribution(name: str, venv: str) -> str:
    """``name version (licence)`` of an installed distribution (``venv="libero"``, ``"aloha"``: as that suite's venv
    sees it, its own site-packages first)."""
    import importlib.metadata as md

    from molmo_lerobot.suites.aloha import aloha_venv
    from molmo_lerobot.suites.libero import libero_venv

    own = {"libero": libero_venv, "aloha": aloha_venv}.get(venv)
    path = [str(p) for p in own().glob("lib/python*/site-packages")] if own else []
    found = next(iter(md.distributions(name=name, path=[*path, *sys.path])), None)
    if found is None:
        return f"{name} (not installed{f'; make .{venv}-venv' if own else ''})"
    meta = found.metadata
    licence = meta.get("License-Expression") or meta.get("License") or "licence not declared"
    return f"{name} {found.version} ({licence})"


def _validate_suite(name: str, *, schema_only: bool, overrides: list[str] | None = None) -> int:
    """``molmo-bench validate <suite benchmark>``: the options, then the planned episodes against the task
    catalogue the suite's own env lists (one line per problem naming the episode and field; exit 2)."""
    from molmo_lerobot.config import ConfigError, compose
    from molmo_lerobot.run_config import RunConfig, RunConfigError
    from molmo_lerobot.suites.benchmark import (
        SUITES,
        SuiteBenchmarkError,
        plan_problems,
        plan_suite_benchmark,
        suite_options,
        suite_tasks,
        task_label,
    )

    try:
        config = RunConfig.of(compose([f"benchmark={name}", *(overrides or [])]))
        kind_name = str(config.benchmark.model_dump().get("suite"))
        options = suite_options(config)
    except (ConfigError, RunConfigError, SuiteBenchmarkError) as exc:
        print(f"molmo-bench: error: {exc}", file=sys.stderr)
        return INVALID
    kind = SUITES[kind_name]
    print(f"benchmark  {name}  (env suite {kind_name}: conf/benchmark/{name}.yaml)")
    print("options    " + ", ".join(f"{k}={v}" for k, v in options.items()))
    if schema_only:
        print("checked    options only (the task catalogue is the suite env's: run without --schema-only)")
        return 0
    from molmo_lerobot.errors import InfrastructureError
    from molmo_lerobot.suites.pipe import SuiteError

    try:
        tasks = suite_tasks(config)
    except (InfrastructureError, SuiteError, OSError, ImportError) as exc:
        print(f"molmo-bench: error: {name}: the suite's task catalogue could not be read: {exc}", file=sys.stderr)
        return INVALID
    bench = plan_suite_benchmark(config, tasks)
    problems = plan_problems(bench, tasks)
    if problems:
        for line in problems:
            print(line, file=sys.stderr)
        print(f"molmo-bench: {len(problems)} problem{'s' * (len(problems) != 1)}", file=sys.stderr)
        return INVALID
    labels = Counter(task_label(e) for e in bench.episodes)
    horizons = sorted({e.horizon for e in bench.episodes})
    print(f"episodes   {len(bench.episodes)} over {len(tasks)} tasks ({options['episodes_per_task']} per task, "
          f"seed {config.seed})")
    shown = list(labels.items())
    print("tasks      " + ", ".join(f"{k} ({v})" for k, v in shown[:12]) + (", ..." if len(shown) > 12 else ""))
    print(f"horizon    {', '.join(map(str, horizons))} (LeRobot's step limit {kind.benchmarks[name]})")
    print(f"sha256     {bench.sha256}")
    print("checked    options and episode plan against the suite's task catalogue: ok")
    return 0


def _validate(path: str, *, schema_only: bool, overrides: list[str] | None = None) -> int:
    plugins, ctx = Plugins(), None
    if not schema_only:
        from molmo_lerobot.config import ConfigError, compose
        from molmo_lerobot.context import RunContext

        try:  # the run's plugins (with its pins) and where MolmoSpaces data lives, as a run would see them
            ctx = RunContext.build(compose(list(overrides or [])))
        except (ConfigError, ValueError, LookupError) as exc:
            print(f"molmo-bench: error: {exc}", file=sys.stderr)
            return 2
        plugins = ctx.plugins
    from molmo_lerobot.runner.episode import EpisodeSetupError, load_run_benchmark

    try:  # molmo-eval's and the Gymnasium env's lookup: a path, else a shipped benchmark's name
        bench = load_run_benchmark(path, plugins)
    except BenchmarkError as exc:
        return _report(exc.problems, INVALID)
    except (PluginConflict, EpisodeSetupError) as exc:
        print(f"molmo-bench: error: {exc}", file=sys.stderr)
        return INVALID
    if ctx is not None:
        from molmo_lerobot.benchmark.validate import validate_benchmark

        try:
            found = validate_benchmark(bench, plugins, ctx)
        except PluginConflict as exc:
            print(f"molmo-bench: error: {exc}", file=sys.stderr)
            return INVALID
        problems = [p for p in found if not p.warning]
        if problems:
            for rec in plugins.broken():
                print(f"note: plugin {rec.name!r} from {rec.distribution} failed to load: {rec.error}", file=sys.stderr)
            return _report(problems, INVALID)
        warnings = [p for p in found if p.warning]
        lines = _grouped(warnings)
        for line in lines:  # valid, but not runnable here as it stands: one line per missing thing
            print(line, file=sys.stderr)
    _print_summary(bench)
    if schema_only:
        print("checked    schema only")
    elif warnings:
        n_eps = len({p.episode_index for p in warnings})
        print(f"checked    valid; {n_eps} of {len(bench.episodes)} episodes cannot run here yet "
              f"({len(lines)} warning{'s' * (len(lines) != 1)} above)")
    else:
        print("checked    schema and installed plugins: ok")
    return 0


def _grouped(warnings: list[Problem]) -> list[str]:
    """One ``warning:`` line per (file, field, message), listing the episodes it concerns."""
    groups: dict[tuple[str, str | None, str], list[int | None]] = {}
    for p in warnings:
        groups.setdefault((p.file, p.field, p.message), []).append(p.episode_index)
    lines = []
    for (file, field, message), eps in groups.items():
        shown = ", ".join(map(str, eps[:10])) + (", ..." if len(eps) > 10 else "")
        where = f"episode{'s' * (len(eps) != 1)} {shown}"
        lines.append(f"warning: {file}: {where}: " + (f"field {field}: " if field else "") + message)
    return lines


def _report(problems: list[Problem], code: int = 1) -> int:
    for p in problems:
        print(p, file=sys.stderr)
    n_eps = len({p.episode_index for p in problems if p.episode_index is not None})
    tail = f" in {n_eps} episode{'s' * (n_eps != 1)}" if n_eps else ""
    print(f"molmo-bench: {len(problems)} problem{'s' * (len(problems) != 1)}{tail}", file=sys.stderr)
    return code


def _print_summary(bench: Benchmark) -> None:
    houses = {ep.house_index for ep in bench.episodes}
    robots = Counter(ep.robot.robot_name for ep in bench.episodes)
    cams = Counter(cam.name for ep in bench.episodes for cam in ep.cameras)
    print(f"benchmark  {bench.name}  ({bench.path})")
    print(f"episodes   {len(bench.episodes)} over {len(houses)} houses")
    tasks = Counter(_task_label(ep.task.task_cls, ep.task.task_type) for ep in bench.episodes)
    print("tasks      " + ", ".join(f"{k} ({v})" for k, v in tasks.items()))
    print("robots     " + ", ".join(f"{k} ({v})" for k, v in robots.items()))
    print("cameras    " + ", ".join(f"{k} ({v})" for k, v in cams.items()))
    print(f"sha256     {bench.sha256}")


def _task_label(task_cls: str, task_type: str | None) -> str:
    """A short task name for known classes (``pick``), else the class path."""
    return NATIVE_TASK_CLS.get(task_cls) or known_task_name(task_cls, task_type) or task_cls


def _generate(args: argparse.Namespace) -> int:
    from molmo_lerobot.benchmark.output import write_benchmark

    if args.houses < 1 or args.episodes_per_house < 1:
        print("molmo-bench: error: --houses and --episodes-per-house must be >= 1", file=sys.stderr)
        return 2
    if not args.out and not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", args.name):
        print(f"molmo-bench: error: --name {args.name!r} names the output directory: use letters, digits, '.', '_' "
              "and '-' (or give --out)", file=sys.stderr)
        return 2
    out: Path = args.out or Path("benchmarks") / args.name
    if out.exists() and not args.force:
        print(f"molmo-bench: error: {out} exists (use --force to replace it)", file=sys.stderr)
        return 2
    try:
        episodes, metadata = GENERATORS[args.generator].generate(args.task, args.houses, args.episodes_per_house,
                                                                 args.seed, args.name)
    except (ValueError, LookupError) as exc:
        print(f"molmo-bench: error: {exc}", file=sys.stderr)
        return 2
    plugins = Plugins()
    bad: list[Problem] = []
    for i, ep in enumerate(episodes):
        try:
            parse_episode(ep, plugins)
        except ValidationError as exc:  # a generator bug, reported per field
            bad.extend(Problem("<generated>", msg, i, loc) for loc, msg in validation_messages(exc))
    if bad:
        return _report(bad)

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o777 & ~umask)  # mkdtemp makes it private; the result is an ordinary directory
    try:
        write_benchmark(tmp, episodes, metadata)
        bench = load_benchmark(tmp, plugins)
        if out.exists():
            shutil.rmtree(out)
        os.replace(tmp, out)
    except BenchmarkError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        return _report(exc.problems)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    bench.path = out
    if bench.metadata is None or not bench.metadata.name:
        bench.name = out.name
    _print_summary(bench)
    return 0


if __name__ == "__main__":
    sys.exit(main())
