"""``molmo-resources``: pack, install, verify and list resources; generate built-in grasps.

Errors exit with status 1 and one line on stderr (``molmo-resources: error: …``), no traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from molmo_lerobot.paths import molmospaces_assets_dir
from molmo_lerobot.resources import molmospaces as ms


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="molmo-resources",
                                description="Pack, install, verify and list resources; generate built-in grasps.")
    sub = p.add_subparsers(dest="command", required=True)

    pk = sub.add_parser("pack", help="archive a directory tree into a remote as a new version")
    pk.add_argument("src", type=Path)
    pk.add_argument("--remote", required=True, help="directory, file:// URL or hf://datasets/<ns>/<repo>[/<prefix>]")
    pk.add_argument("--data-type", required=True)
    pk.add_argument("--source", required=True)
    pk.add_argument("--version", required=True)
    pk.add_argument("--link", choices=("dir", "file"), default="dir",
                    help="install as one directory link (objects, grasps) or per-file links (scenes, robots)")
    pk.add_argument("--uid-depth", type=int, default=0, help="path component that names the UID (default 0)")
    pk.add_argument("--max-archive-mb", type=float, default=64.0)

    ins = sub.add_parser("install", help="install DATA_TYPE/SOURCE@VERSION (or a preset's versions) into a cache "
                                         "and install dir")
    ins.add_argument("spec", nargs="*", metavar="DATA_TYPE/SOURCE@VERSION")
    ins.add_argument("--preset", help="'molmospaces' (the versions MolmoSpaces pins, into its assets dir layout) or a "
                                      "JSON version table {data_type: {source: version}}")
    ins.add_argument("--remote", help="directory, file://, http(s):// bucket or hf://datasets/<ns>/<repo>[/<prefix>] "
                                      f"(with --preset: default MolmoSpaces' bucket {ms.BUCKET_URL})")
    ins.add_argument("--cache-dir", type=Path,
                     help="with --preset: default $MLSPACES_CACHE_DIR or ~/.cache/molmo-spaces-resources "
                          "(shared with molmospaces-resources)")
    ins.add_argument("--install-dir", type=Path, help="with --preset: default MolmoSpaces' assets dir "
                                                      "($MLSPACES_ASSETS_DIR or ours)")
    ins.add_argument("--on-demand", action="store_true", help="fetch manifests and index only; archives on first use")
    ins.add_argument("--eager", action="store_true", help="with --preset: extract every archive now, also of sources "
                                                          "MolmoSpaces installs on demand")
    ins.add_argument("--uid", action="append", default=[], help="also install the archives holding this UID "
                                                                "(repeatable; the rest stays on demand)")
    ins.add_argument("--workers", type=int, default=4)
    ins.add_argument("--lock-timeout", type=float, default=600.0)
    ins.add_argument("--no-lock", action="store_true", help="read a cache a leader filled; never write")
    ins.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None)

    ver = sub.add_parser("verify", help="recheck installed files against their manifests")
    ver.add_argument("--cache-dir", required=True, type=Path)
    ver.add_argument("--install-dir", type=Path)

    ls = sub.add_parser("list", help="list what the cache holds and what the install dir points at")
    ls.add_argument("--cache-dir", required=True, type=Path)
    ls.add_argument("--install-dir", type=Path)
    ls.add_argument("--remote", help="also list the versions available on this remote")
    ls.add_argument("--json", action="store_true")

    gr = sub.add_parser("grasps", help="grasp libraries")
    gsub = gr.add_subparsers(dest="grasps_command", required=True)
    gen = gsub.add_parser("generate", help="write analytic grasps of the built-in objects as NPZ files")
    gen.add_argument("--out", type=Path, default=None, help="grasp library dir (default: the built-in grasp dir)")
    gen.add_argument("--robot", default="franka")
    return p


def _run(args: argparse.Namespace) -> int:
    from molmo_lerobot.resources import ResourceManager, ResourceSpec, open_remote, pack

    if args.command == "pack":
        manifest = pack(args.src, args.remote, ResourceSpec(args.data_type, args.source, args.version),
                        link=args.link, uid_depth=args.uid_depth,
                        max_archive_bytes=int(args.max_archive_mb * (1 << 20)))
        total = sum(a["size"] for a in manifest["archives"].values())
        print(f"packed {args.src} as {args.data_type}/{args.source}@{args.version}: "
              f"{len(manifest['archives'])} archives, {total} bytes → {args.remote}")
        return 0
    if args.command == "install":
        return _install(args)
    if args.command == "verify":
        mgr = ResourceManager(args.cache_dir, args.install_dir)
        problems = mgr.verify()
        for line in problems:
            print(line)
        n = sum(len(v) for s in mgr.installed().values() for v in s.values())
        print(f"verified {n} installed versions: {len(problems)} problems")
        return 1 if problems else 0
    if args.command == "list":
        mgr = ResourceManager(args.cache_dir, args.install_dir)
        listing: dict[str, dict[str, dict[str, Any]]] = {"cache": mgr.installed(), "linked": mgr.linked()}
        if args.remote:
            files = open_remote(args.remote).list_files()
            remote: dict[str, dict[str, list[str]]] = {}
            for f in files:
                parts = f.split("/")
                if len(parts) == 4 and parts[3] in ("manifest.json", ms.REMOTE_MANIFEST):
                    remote.setdefault(parts[0], {}).setdefault(parts[1], []).append(parts[2])
            listing["remote"] = remote
        if args.json:
            print(json.dumps(listing, indent=1, sort_keys=True))
            return 0
        linked = listing["linked"]
        for data_type, sources in sorted(listing["cache"].items()):
            for source, versions in sorted(sources.items()):
                for v in versions:
                    mark = " (linked)" if linked.get(data_type, {}).get(source) == v else ""
                    complete = "complete" if mgr.is_complete(f"{data_type}/{source}@{v}") else "on demand"
                    print(f"{data_type}/{source}@{v}  {complete}{mark}")
        for data_type, sources in sorted(listing.get("remote", {}).items()):
            for source, versions in sorted(sources.items()):
                print(f"remote {data_type}/{source}: {', '.join(sorted(versions))}")
        return 0
    if args.command == "grasps":
        from molmo_lerobot.assets.grasps import generate_builtin_grasps

        written = generate_builtin_grasps(args.out, robot=args.robot)
        out = written[0].parent if written else args.out
        print(f"wrote analytic grasps for {len(written)} built-in objects → {out}")
        return 0
    raise AssertionError(args.command)


def _install(args: argparse.Namespace) -> int:
    from molmo_lerobot.resources import ResourceError, ResourceManager

    specs: list[tuple[str, bool]] = [(s, args.on_demand or bool(args.uid)) for s in args.spec]
    if args.preset:
        table = ms.VERSIONS if args.preset == "molmospaces" else ms.read_versions_file(Path(args.preset))
        for data_type, sources in table.items():
            for source, version in sources.items():
                eager = args.eager or ms.behaviour(data_type, source)[1]
                specs.append((f"{data_type}/{source}@{version}", args.on_demand or not eager))
        remote = args.remote or ms.BUCKET_URL
        cache = args.cache_dir or ms.cache_dir()
        install = args.install_dir or molmospaces_assets_dir()
    else:
        missing = [flag for flag, value in (("--remote", args.remote), ("--cache-dir", args.cache_dir),
                                            ("--install-dir", args.install_dir)) if value is None]
        if missing or not specs:
            raise ResourceError(f"install needs {', '.join(missing) or 'DATA_TYPE/SOURCE@VERSION'} (or --preset)")
        remote, cache, install = args.remote, args.cache_dir, args.install_dir
    mgr = ResourceManager(cache, install, remote, use_lock=not args.no_lock, workers=args.workers,
                          progress=args.progress, lock_timeout=args.lock_timeout)
    parsed = []
    for text, on_demand in specs:
        r = mgr.install(text, on_demand=on_demand)
        parsed.append(r.spec)
        mode = "on demand" if r.on_demand else "eager"
        if args.preset and r.on_demand and not args.on_demand:  # what MolmoSpaces extracts at setup anyway
            setup = ms.setup_archives(r.spec.data_type, sorted(mgr.manifest(r.spec)["archives"]))
            if setup:
                mode += f", {mgr.ensure_archives(r.spec, setup)} of its {len(setup)} base archives extracted"
        print(f"installed {r.spec} ({mode}): {r.extracted} archives extracted, {r.present} already present → {r.path}")
    for uid in args.uid:
        holders = [s for s in parsed if mgr.index(s).archives_for_uid(uid)]
        if not holders:
            raise ResourceError(f"UID {uid!r} is in none of {', '.join(map(str, parsed))}")
        for spec in holders:
            files = mgr.ensure_uid(spec, uid)
            print(f"installed UID {uid} from {spec}: {len(files)} files")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from molmo_lerobot.resources.errors import ResourceError

    try:
        return _run(args)
    except (ResourceError, OSError, ValueError, LookupError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"molmo-resources: error: {msg}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("molmo-resources: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
