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
with one of the plugins' generators (``molmo_generators``; default ``v1``) and validates it; the output
directory appears only once it is complete. Each shipped benchmark is what its generator writes for the arguments its
``benchmark_metadata.json`` records (``generator``), byte for byte; the ``*_v3`` benchmarks are the
``*_v2`` episodes with render profile v3 named in their metadata.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import sys
import tempfile
from collections import Counter
from pathlib import Path

from pydantic import ValidationError

from molmo_lerobot.benchmark.load import Benchmark, BenchmarkError, Problem, load_benchmark, validation_messages
from molmo_lerobot.benchmark.molmospaces import known_task_name
from molmo_lerobot.benchmark.schema import NATIVE_TASK_CLS
from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.benchmark_kinds import benchmark_kind, benchmark_kinds
from molmo_lerobot.plugins import PluginConflict, PluginError, Plugins

#: the exit status for a benchmark that cannot be run (``molmo-eval`` refuses it with the same)
INVALID = 2


def main(argv: list[str] | None = None) -> int:
    plugins = Plugins()
    parser = argparse.ArgumentParser(prog="molmo-bench", description="Check and make benchmarks.")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="every benchmark molmo-eval runs: registered directories and env suites")
    val = sub.add_parser("validate", help="check a benchmark: a shipped name, a directory or a JSON file")
    val.add_argument("path", metavar="BENCHMARK", help="a shipped benchmark's name (pick_v2) or a path")
    val.add_argument("--schema-only", action="store_true", help="skip the checks against installed plugins")
    val.add_argument("overrides", nargs="*", metavar="KEY=VALUE",
                     help="run-config overrides that locate data (molmospaces.assets_dir=…, scene_xml_paths=[…], …)")
    gen = sub.add_parser("generate", help="generate a benchmark deterministically",
                         epilog="generators: " + "; ".join(_generators(plugins)))
    gen.add_argument("generator", nargs="?", default="v1", help="which generator (default v1)")
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
        kind = None if Path(args.path).exists() else benchmark_kind(Plugins(), args.path)
        if kind is not None and kind.name != "episodes":
            return _validate_kind(args.path, schema_only=args.schema_only, overrides=args.overrides)
        return _validate(args.path, schema_only=args.schema_only, overrides=args.overrides)
    return _generate(args, plugins)


def _generators(plugins: Plugins) -> list[str]:
    """One line per generator ``molmo-bench generate`` runs: name, description, tasks."""
    out = []
    for name in plugins.names("generator"):
        try:
            g = plugins.resolve("generator", name)
        except PluginError as exc:  # a clash: listed, refused when run
            out.append(f"{name}: {exc}")
            continue
        out.append(f"{name}: {g.description} (--task {', '.join(g.tasks)})")
    return out


def _list() -> int:
    """One line per benchmark of every benchmark kind (name, kind, episodes, horizon, where), then where each
    kind's env and assets come from."""
    plugins = Plugins()
    rows = [("benchmark", "kind", "episodes", "horizon", "where")]
    about = []
    for kind in benchmark_kinds(plugins):
        rows += [(name, row.kind, row.episodes, row.horizon, row.where)
                 for name, row in kind.benchmarks(plugins).items() if benchmark_kind(plugins, name) is kind]
        about += kind.about(plugins)
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row[:4], widths, strict=True)) + "  " + row[4])
    print()
    print("\n".join(about))
    return 0


def _validate_kind(name: str, *, schema_only: bool, overrides: list[str] | None = None) -> int:
    """``molmo-bench validate <name>`` of a benchmark kind other than episode files: its options, then its
    episodes planned and checked by the kind (an env suite's against the task catalogue its own env lists;
    one line per problem naming the episode and field; exit 2)."""
    from molmo_lerobot.benchmark_kinds import BenchmarkKindError, run_kind
    from molmo_lerobot.config import ConfigError, compose
    from molmo_lerobot.errors import InfrastructureError
    from molmo_lerobot.run_config import RunConfig, RunConfigError
    from molmo_lerobot.suites.pipe import SuiteError

    try:
        config = RunConfig.of(compose([f"benchmark={name}", *(overrides or [])]))
        kind = run_kind(Plugins(), config)
        options = kind.options_of(config)
    except (ConfigError, RunConfigError, BenchmarkKindError) as exc:
        print(f"molmo-bench: error: {exc}", file=sys.stderr)
        return INVALID
    print(f"benchmark  {name}  (benchmark kind {kind.name}: {kind.description})")
    print("options    " + ", ".join(f"{k}={v}" for k, v in options.model_dump(exclude={"name", "path"}).items()))
    if schema_only:
        print("checked    options only (run without --schema-only to plan and check its episodes)")
        return 0
    try:
        lines, problems = kind.validate(config)
    except (InfrastructureError, SuiteError, OSError, ImportError) as exc:
        print(f"molmo-bench: error: {name}: the benchmark's episodes could not be planned: {exc}", file=sys.stderr)
        return INVALID
    if problems:
        for line in problems:
            print(line, file=sys.stderr)
        print(f"molmo-bench: {len(problems)} problem{'s' * (len(problems) != 1)}", file=sys.stderr)
        return INVALID
    print("\n".join(lines))
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


def _generate(args: argparse.Namespace, plugins: Plugins) -> int:
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
        generator = plugins.resolve("generator", args.generator)
        episodes, metadata = generator.run(args.task, args.houses, args.episodes_per_house, args.seed, args.name)
    except (ValueError, LookupError) as exc:
        print(f"molmo-bench: error: {exc}", file=sys.stderr)
        return 2
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
