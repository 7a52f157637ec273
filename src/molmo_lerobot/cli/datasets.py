"""``molmo-datasets``: the dataset store's namespaces and datasets, local and on the Hub
(:mod:`molmo_lerobot.namespaces`, Minari's namespace API).

  molmo-datasets list [PREFIX] [--remote [hf://OWNER]]
  molmo-datasets show NAMESPACE_OR_DATASET_ID
  molmo-datasets create|update|delete NAMESPACE [--description D] [--set KEY=VALUE ...]
  molmo-datasets delete-dataset DATASET_ID

Every id, name and value it prints from the store or the Hub is shown escaped when it holds a
control character; every error is one line (exit status 2, 1 for a failing filesystem).
  molmo-datasets push|pull ID [--remote hf://OWNER] [--force]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import warnings
from pathlib import Path
from typing import Any

_EPILOG = """the store: --root, else $MOLMO_DATASETS_PATH, else $MOLMO_LEROBOT_HOME/datasets, else
~/.cache/molmo_lerobot/datasets; the Hub remote: --remote, else $MOLMO_DATASETS_REMOTE (hf://<user or org>;
the top namespace is the dataset repo <owner>/<top>, the rest folders in it). Record into the store with
molmo-eval record=true dataset_id=ns/sub/name; load with LeRobotDataset(ID, root=<store>/ID)."""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="molmo-datasets", description="Organise, list, share and fetch recorded "
                                "eval datasets by namespace (Minari's namespace API).", epilog=_EPILOG)
    p.add_argument("--root", help="the local dataset store (default: see below)")
    sub = p.add_subparsers(dest="command", required=True)
    ls = sub.add_parser("list", help="namespaces and datasets, local or (--remote) on the Hub")
    ls.add_argument("prefix", nargs="?", help="only datasets under this namespace")
    ls.add_argument("--remote", nargs="?", const="", help="list the Hub's (hf://OWNER, default $MOLMO_DATASETS_REMOTE)")
    show = sub.add_parser("show", help="print a namespace's metadata, or a dataset's metadata and summary")
    show.add_argument("id", help="a namespace or a dataset id")
    for name, text in (("create", "create a namespace (and its parents)"),
                       ("update", "replace a namespace's metadata"), ("delete", "delete an empty namespace")):
        c = sub.add_parser(name, help=text)
        c.add_argument("namespace")
        if name in ("create", "update"):
            c.add_argument("--description")
            c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                           help="more metadata (VALUE as JSON when it parses, else text; not the keys "
                                "'namespace' and 'description')")
    d = sub.add_parser("delete-dataset", help="remove a dataset from the store")
    d.add_argument("dataset_id")
    for name, text in (("push", "upload a namespace (parents first) or a dataset (with its namespaces)"),
                       ("pull", "download a namespace's metadata or a dataset (with its namespaces' metadata)")):
        c = sub.add_parser(name, help=text)
        c.add_argument("id", help="a namespace or a dataset id")
        c.add_argument("--remote", help="hf://OWNER (default $MOLMO_DATASETS_REMOTE)")
        c.add_argument("--force", action="store_true", help="pull: replace what is stored locally")
    return p


def _metadata(pairs: list[str]) -> dict:
    from molmo_lerobot.namespaces import NamespaceError, shown

    out = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise NamespaceError(f"--set {shown(pair)}: expected KEY=VALUE")
        if key in ("namespace", "description"):  # the arguments of Minari's create_namespace
            raise NamespaceError(f"--set {shown(pair)}: {key!r} is not a metadata key here (" + (
                "it is the namespace's id)" if key == "namespace" else "give it with --description)"))
        try:
            out[key] = json.loads(value)
        except ValueError:
            out[key] = value
    return out


def _printable(value: Any) -> str:
    """``value`` as text for the terminal: as is, or escaped (``repr``) when it holds a control character."""
    text = str(value)
    return text if text.isprintable() else repr(text)


def _dataset_row(dataset_id: str, meta: dict[str, Any]) -> str:
    """``list``'s line for a dataset: its id, benchmark and policy, and score, from whatever its metadata holds."""
    row = f"dataset    {_printable(dataset_id)}"
    bench = meta.get("benchmark")
    if meta.get("policy"):
        row += f"  {_printable(bench.get('name') if isinstance(bench, dict) else None)} · {_printable(meta['policy'])}"
    rate = meta.get("success_rate")
    if isinstance(rate, float | int) and not isinstance(rate, bool):
        row += f"  success {rate:.3f} ({_printable(meta.get('n_episodes'))} episodes)"
    return row


def _show(store: Any, ident: str) -> dict[str, Any]:
    """A namespace's metadata, or a dataset's summary: where it is, the run that recorded it here, LeRobot's
    counts from ``meta/info.json`` and its dataset-level metadata."""
    from molmo_lerobot import namespaces as ns

    with contextlib.suppress(ns.NamespaceError):
        ns.validate_namespace(ident)
        if store.is_namespace(ident):
            return store.get_namespace_metadata(ident)
    try:
        ns.parse_dataset_id(ident)
    except ns.NamespaceError as exc:
        raise ns.NamespaceError(f"{ns.shown(ident)} is neither a namespace nor a dataset id ({exc})") from None
    if not store.is_dataset(ident) and not os.path.lexists(store.path(ident)):
        raise ns.NamespaceError(f"no namespace or dataset {ns.shown(ident)} in {store.root}")
    path = store.existing_dataset(ident)
    info = store.dataset_info(ident)
    try:
        run_dir: str | None = str(store.run_dir(ident))
    except ns.NamespaceError:
        run_dir = None  # pulled or copied in
    return {"dataset_id": ident, "path": str(path), "run_dir": run_dir,
            **{key: info.get(key) for key in ("codebase_version", "robot_type", "fps", "total_episodes",
                                                "total_frames", "total_tasks")},
            "metadata": store.dataset_metadata(ident)}


def _run(args: argparse.Namespace) -> None:
    from molmo_lerobot import namespaces as ns

    store = ns.DatasetStore()
    if args.command == "list":
        datasets: list[str] | dict[str, dict[str, Any]]
        where: str | Path
        if args.remote is not None:
            hub = ns.HubRemote.from_remote(args.remote or None)
            names, datasets = sorted(set(hub.list_namespaces())), hub.list_datasets(args.prefix)
            where = f"hf://{hub.owner}"
        else:
            names, datasets, where = store.list_local_namespaces(), store.list_local_datasets(args.prefix), store.root
        print(f"# {where}")
        for name in names:
            print(f"namespace  {_printable(name)}")
        for dataset_id in datasets:
            print(_dataset_row(dataset_id, datasets[dataset_id] if isinstance(datasets, dict) else {}))
    elif args.command == "show":
        print(json.dumps(_show(store, args.id), indent=2))
    elif args.command == "create":
        store.create_namespace(args.namespace, args.description, **_metadata(args.set))
    elif args.command == "update":
        store.update_namespace_metadata(args.namespace, args.description, **_metadata(args.set))
    elif args.command == "delete":
        store.delete_namespace(args.namespace)
    elif args.command == "delete-dataset":
        store.delete_dataset(args.dataset_id)
    elif args.command == "push":
        if store.is_dataset(args.id):
            ns.upload_dataset(args.id, store=store, remote=args.remote)
        else:  # a namespace, or one line saying why it cannot be pushed
            ns.upload_namespace(args.id, store=store, remote=args.remote)
    elif args.command == "pull":
        hub = ns.HubRemote.from_remote(args.remote)
        if args.id in hub.list_namespaces():
            ns.download_namespace_metadata(args.id, args.force, store=store, remote=args.remote)
        else:
            print(ns.download_dataset(args.id, args.force, store=store, remote=args.remote))


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.root:
        os.environ["MOLMO_DATASETS_PATH"] = args.root
    from molmo_lerobot.namespaces import NamespaceError

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        try:
            _run(args)
        except NamespaceError as exc:
            print(f"molmo-datasets: error: {exc}", file=sys.stderr)
            return 2
        except OSError as exc:
            print(f"molmo-datasets: error: {type(exc).__name__}: {exc}".splitlines()[0], file=sys.stderr)
            return 1
    for message in dict.fromkeys(str(w.message) for w in caught if issubclass(w.category, UserWarning)):
        print(f"molmo-datasets: warning: {message}", file=sys.stderr)  # each once (a listing reads a repo twice)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
