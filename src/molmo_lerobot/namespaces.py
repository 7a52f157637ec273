"""Dataset namespaces with Minari's API and semantics, over a local store of LeRobot datasets and the Hub.

A dataset id is ``ns/sub/name``: the namespace ``ns/sub`` is a directory-like prefix that can
hold datasets and other namespaces. The local store is a directory (``$MOLMO_DATASETS_PATH``,
else ``$MOLMO_LEROBOT_HOME/datasets``, else ``~/.cache/molmo_lerobot/datasets``; Minari's is
``$MINARI_DATASETS_PATH``) where dataset ``ns/sub/name`` is the LeRobot v3 dataset
``<root>/ns/sub/name`` (``LeRobotDataset(repo_id, root=<root>/ns/sub/name)`` loads it) and each
namespace directory holds a ``namespace_metadata.json``. The module-level functions are
Minari's (``minari.namespace``) with its names, arguments, outcomes and files, on the default
store; :class:`DatasetStore` is the same on any root. Deliberate differences (checked by
``tests/test_namespaces_minari.py``): a namespace id with an empty part (``a//b``, which Minari
accepts and then cannot find again) is refused, and a namespace never goes inside or over a
dataset (Minari writes its metadata file into the dataset's directory).

A LeRobot dataset is a directory holding ``meta/info.json`` (Minari's marker is ``data/``); the
namespace listing never descends into one. Every error is one line naming the id
(:class:`NamespaceError`); every write goes through :mod:`molmo_lerobot.fileio`.

The Hub (:class:`HubRemote`, a remote ``hf://<user or org>``, ``$MOLMO_DATASETS_REMOTE``) maps
namespaces as Minari's Hugging Face storage does: the top-level namespace ``ns`` is the dataset
repo ``<owner>/ns``; nested namespaces and datasets are folders in it (``sub/``,
``sub/name/``), each namespace folder with its ``namespace_metadata.json``; the repo's root
``namespace_metadata.json`` also registers every nested namespace (``namespaces``) and dataset
(``datasets``) uploaded into it, which is what :func:`list_remote_namespaces` reads.
"""

from __future__ import annotations

import contextlib
import json
import os
import posixpath
import re
import shutil
import uuid
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from molmo_lerobot import fileio
from molmo_lerobot.errors import MolmoError
from molmo_lerobot.paths import home_dir

NAMESPACE_REGEX = re.compile(r"[-_\w][-_\w/]*[-_\w]+")  # Minari's
NAMESPACE_METADATA_FILENAME = "namespace_metadata.json"
#: the dataset-level metadata in a stored dataset (benchmark, policy, score, run)
DATASET_METADATA_FILE = "meta/eval/dataset_metadata.json"
#: local only (hidden: never pushed): the absolute run directory a stored recording came from
RUN_DIR_FILE = ".molmo_run_dir"
_NAME_RE = re.compile(r"[-_\w][-_.\w]*")


class NamespaceError(MolmoError, ValueError):
    """An invalid, missing, existing or non-empty namespace or dataset; the one-line message names it."""


class NamespaceTypeError(NamespaceError, TypeError):
    """No namespace given (``None``), as Minari's ``TypeError``."""


# -- ids ----------------------------------------------------------------------------------------
def validate_namespace(namespace: str | None) -> None:
    """Raise unless ``namespace`` is a namespace id: Minari's ``[-_\\w][-_\\w/]*[-_\\w]+`` with no empty part."""
    if namespace is None:
        raise NamespaceTypeError("namespace cannot be None")
    if not isinstance(namespace, str) or not NAMESPACE_REGEX.fullmatch(namespace) or "//" in namespace:
        raise NamespaceError(f"malformed namespace {namespace!r}: use letters, digits, '-', '_' and '/' between "
                             "parts (at least 2 characters, no leading, trailing or double '/')")


def parse_dataset_id(dataset_id: str) -> tuple[str | None, str]:
    """Split ``ns/sub/name`` into ``("ns/sub", "name")``; ``name`` alone has no namespace."""
    if not isinstance(dataset_id, str) or not dataset_id:
        raise NamespaceError(f"malformed dataset id {dataset_id!r}: expected [namespace/]name")
    namespace, _, name = dataset_id.rpartition("/")
    if not _NAME_RE.fullmatch(name):
        raise NamespaceError(f"malformed dataset id {dataset_id!r}: the name {name!r} must start with a letter, "
                             "digit, '-' or '_' and use only those and '.'")
    if namespace or dataset_id.startswith("/"):
        try:
            validate_namespace(namespace)
        except NamespaceError as exc:
            raise NamespaceError(f"malformed dataset id {dataset_id!r}: {exc}") from None
    return namespace or None, name


def namespace_hierarchy(namespace: str | None) -> Iterator[str]:
    """``a``, ``a/b``, ``a/b/c`` for ``a/b/c``: the namespace's parents, then itself (Minari's order)."""
    if namespace is None:
        return
    parts = namespace.split("/")
    for i in range(len(parts)):
        yield posixpath.join(*parts[: i + 1])  # as Minari's os.path.join (``/ab`` gives ``""``, ``ab``)


def is_dataset_dir(path: Path) -> bool:
    """Whether ``path`` is a LeRobot dataset (holds ``meta/info.json``)."""
    return (Path(path) / "meta" / "info.json").is_file()


def default_root() -> Path:
    """``$MOLMO_DATASETS_PATH``, else ``$MOLMO_LEROBOT_HOME/datasets``, else ``~/.cache/molmo_lerobot/datasets``."""
    if os.environ.get("MOLMO_DATASETS_PATH"):
        return Path(os.environ["MOLMO_DATASETS_PATH"]).expanduser()
    return home_dir().expanduser() / "datasets"


def _dump(metadata: dict[str, Any]) -> str:
    return json.dumps(metadata)  # Minari's json.dump defaults: the same bytes


# -- the local store ----------------------------------------------------------------------------
class DatasetStore:
    """The namespaces and datasets under ``root`` (default :func:`default_root`)."""

    def __init__(self, root: str | os.PathLike | None = None) -> None:
        self.root = Path(root).expanduser() if root is not None else default_root()

    def path(self, ident: str | None = None) -> Path:
        return self.root / ident if ident else self.root

    def _write(self, rel: str, text: str) -> None:
        fileio.atomic_write(self.root / rel, text, root=self.root)

    def _inside_dataset(self, ident: str) -> str | None:
        """The stored dataset that ``ident`` is, or lies inside of, if any."""
        for parent in namespace_hierarchy(ident):
            if is_dataset_dir(self.path(parent)):
                return parent
        return None

    def is_namespace(self, namespace: str) -> bool:
        metadata = self.path(namespace) / NAMESPACE_METADATA_FILENAME
        return metadata.is_file() and self._inside_dataset(namespace) is None

    def is_dataset(self, dataset_id: str) -> bool:
        parse_dataset_id(dataset_id)
        return is_dataset_dir(self.path(dataset_id))

    # Minari's namespace functions ---------------------------------------------------------------
    def create_namespace(self, namespace: str, description: str | None = None, **kwargs: Any) -> None:
        """Create ``namespace`` (its missing parents too, with empty metadata); an existing one is an error."""
        validate_namespace(namespace)
        if self.is_namespace(namespace):
            raise NamespaceError(f"namespace {namespace!r} already exists in {self.root}")
        inside = self._inside_dataset(namespace)
        if inside is not None:
            raise NamespaceError(f"namespace {namespace!r} collides with the dataset {inside!r} in {self.root}")
        metadata = dict(kwargs)
        if description is not None:
            metadata["description"] = description
        self._write(f"{namespace}/{NAMESPACE_METADATA_FILENAME}", _dump(metadata))
        for parent in namespace_hierarchy(namespace):
            if not self.is_namespace(parent):
                self._write(f"{parent}/{NAMESPACE_METADATA_FILENAME}", _dump({}))

    def update_namespace_metadata(self, namespace: str, description: str | None = None, **kwargs: Any) -> None:
        """Replace ``namespace``'s metadata with ``kwargs`` and ``description`` (null when not given)."""
        self._existing(namespace)
        self._write(f"{namespace}/{NAMESPACE_METADATA_FILENAME}", _dump({**kwargs, "description": description}))

    def get_namespace_metadata(self, namespace: str) -> dict[str, Any]:
        """``namespace``'s metadata."""
        path = self._existing(namespace) / NAMESPACE_METADATA_FILENAME
        try:
            return json.loads(path.read_text())
        except ValueError as exc:
            raise NamespaceError(f"namespace {namespace!r}: {path} is not valid JSON ({exc})") from None

    def delete_namespace(self, namespace: str) -> None:
        """Delete the empty ``namespace`` (a missing one warns, as Minari); one holding anything is an error."""
        validate_namespace(namespace)
        if not self.is_namespace(namespace):
            warnings.warn(f"namespace {namespace!r} does not exist in {self.root}", UserWarning, stacklevel=2)
            return
        directory = self.path(namespace)
        contents = sorted(os.listdir(directory))
        others = [name for name in contents if name != NAMESPACE_METADATA_FILENAME]
        if others:
            shown = ", ".join(others[:5]) + (f" and {len(others) - 5} more" if len(others) > 5 else "")
            raise NamespaceError(f"namespace {namespace!r} is not empty (it holds {shown}); delete its datasets "
                                 "and namespaces first")
        fileio.rmtree(directory, root=self.root)  # empty but for its metadata file

    def list_local_namespaces(self) -> list[str]:
        """Every namespace in the store, sorted; never looks inside a dataset or a hidden directory."""
        return sorted(ident for ident, kind in self._walk() if kind == "namespace")

    def list_local_datasets(self, prefix: str | None = None) -> dict[str, dict[str, Any]]:
        """``{dataset_id: dataset-level metadata}`` of every stored dataset (under ``prefix``), sorted."""
        out = {}
        for ident, kind in sorted(self._walk()):
            if kind == "dataset" and (prefix is None or ident == prefix or ident.startswith(prefix.rstrip("/") + "/")):
                out[ident] = self.dataset_metadata(ident)
        return out

    def _walk(self) -> Iterator[tuple[str, str]]:
        def recurse(rel: str) -> Iterator[tuple[str, str]]:
            directory = self.path(rel)
            with contextlib.suppress(FileNotFoundError, NotADirectoryError):
                for entry in sorted(os.scandir(directory), key=lambda e: e.name):
                    if entry.name.startswith(".") or not entry.is_dir(follow_symlinks=False):
                        continue
                    ident = f"{rel}/{entry.name}" if rel else entry.name
                    if is_dataset_dir(Path(entry.path)):
                        yield ident, "dataset"
                        continue
                    if os.path.isfile(os.path.join(entry.path, NAMESPACE_METADATA_FILENAME)):
                        yield ident, "namespace"
                    yield from recurse(ident)
        yield from recurse("")

    def _existing(self, namespace: str) -> Path:
        validate_namespace(namespace)
        if not self.is_namespace(namespace):
            raise NamespaceError(f"namespace {namespace!r} does not exist in {self.root}")
        return self.path(namespace)

    # datasets -----------------------------------------------------------------------------------
    def dataset_metadata(self, dataset_id: str) -> dict[str, Any]:
        """A stored dataset's dataset-level metadata (``{}`` when it has none)."""
        path = self.path(dataset_id) / DATASET_METADATA_FILE
        try:
            return json.loads(path.read_text())
        except (FileNotFoundError, ValueError):
            return {}

    def run_dir(self, dataset_id: str) -> Path:
        """The run directory a stored recording came from (for ``resume`` and ``molmo-compare``)."""
        if not self.is_dataset(dataset_id):
            raise NamespaceError(f"dataset {dataset_id!r} is not in {self.root}")
        try:
            return Path((self.path(dataset_id) / RUN_DIR_FILE).read_text().strip())
        except FileNotFoundError:
            raise NamespaceError(f"dataset {dataset_id!r} in {self.root} was not recorded by molmo-eval on this "
                                 f"machine (no {RUN_DIR_FILE})") from None

    def check_new_dataset(self, dataset_id: str, run_dir: str | os.PathLike | None = None) -> None:
        """Raise unless ``dataset_id`` can be stored: a valid id whose place is free (or holds the recording
        of ``run_dir``, which a resume replaces) and lies in no other dataset."""
        namespace, _ = parse_dataset_id(dataset_id)
        inside = self._inside_dataset(namespace) if namespace else None
        if inside is not None:
            raise NamespaceError(f"dataset id {dataset_id!r} lies inside the dataset {inside!r} in {self.root}")
        path = self.path(dataset_id)
        if not os.path.lexists(path):
            return
        if is_dataset_dir(path):
            mine = run_dir is not None and _same_dir(self._stored_run_dir(dataset_id), run_dir)
            if not mine:
                raise NamespaceError(f"dataset id {dataset_id!r} collides with an existing dataset in {self.root} "
                                     "(pick another id, or delete that dataset first)")
        elif (path / NAMESPACE_METADATA_FILENAME).is_file():
            raise NamespaceError(f"dataset id {dataset_id!r} collides with the namespace {dataset_id!r} in {self.root}")
        else:
            raise NamespaceError(f"dataset id {dataset_id!r}: {path} exists and is not a dataset; move it away first")

    def _stored_run_dir(self, dataset_id: str) -> str | None:
        try:
            return (self.path(dataset_id) / RUN_DIR_FILE).read_text().strip()
        except OSError:
            return None

    def add_dataset(self, dataset_id: str, source: str | os.PathLike, metadata: dict[str, Any],
                    run_dir: str | os.PathLike | None = None) -> Path:
        """Copy the LeRobot dataset at ``source`` into the store as ``dataset_id`` with its dataset-level
        ``metadata``; missing namespaces are created as Minari creates them (empty metadata). The copy is
        built in a hidden directory of the store and renamed into place, so the store holds the whole
        dataset or none of it; the recording of ``run_dir`` already stored there (a resume) is replaced."""
        source = Path(source)
        self.check_new_dataset(dataset_id, run_dir)
        if not is_dataset_dir(source):
            raise NamespaceError(f"dataset {dataset_id!r}: {source} is not a LeRobot dataset (no meta/info.json)")
        links = [rel for rel, entry in fileio.walk(source).items() if entry[0] == "l"]
        if links:
            raise NamespaceError(f"dataset {dataset_id!r}: {source / links[0]} is a symlink; refusing to store it")
        namespace, _ = parse_dataset_id(dataset_id)
        if namespace is not None and not self.is_namespace(namespace):
            self.create_namespace(namespace)
        staging = fileio.make_dirs(self.root / f".incoming-{uuid.uuid4().hex}", root=self.root)
        try:
            shutil.copytree(source, staging / "dataset", ignore=shutil.ignore_patterns(".*", "images"))
            fileio.atomic_write(staging / "dataset" / DATASET_METADATA_FILE,
                                json.dumps({"dataset_id": dataset_id, **metadata}, indent=2, sort_keys=True),
                                root=staging)
            if run_dir is not None:
                fileio.atomic_write(staging / "dataset" / RUN_DIR_FILE, str(Path(run_dir).resolve()), root=staging)
            target = self.path(dataset_id)
            if is_dataset_dir(target):  # this run's earlier recording (check_new_dataset allowed it)
                fileio.replace(target, staging / "old", root=self.root)
            fileio.replace(staging / "dataset", target, root=self.root)
        finally:
            fileio.rmtree(staging, root=self.root, ignore_errors=True)
        return self.path(dataset_id)

    def delete_dataset(self, dataset_id: str) -> None:
        """Remove a stored dataset (its namespaces stay)."""
        if not self.is_dataset(dataset_id):
            raise NamespaceError(f"dataset {dataset_id!r} is not in {self.root}")
        fileio.rmtree(self.path(dataset_id), root=self.root)


def _same_dir(a: str | os.PathLike | None, b: str | os.PathLike | None) -> bool:
    return a is not None and b is not None and os.path.realpath(a) == os.path.realpath(b)


# -- the Hub ------------------------------------------------------------------------------------
def _decompose(ident: str) -> tuple[str, str]:
    """``ns/sub/name`` -> (repo name ``ns``, path in repo ``sub/name``), as Minari's Hugging Face storage."""
    top, _, rest = ident.partition("/")
    return top, rest


def _join(*parts: str) -> str:
    return "/".join(p for p in parts if p)


class HubRemote:
    """Namespaces and datasets of the Hub user or organisation ``owner`` (the remote ``hf://<owner>``)."""

    def __init__(self, owner: str, token: str | None = None, private: bool = False) -> None:
        from huggingface_hub import HfApi

        self.owner, self.private = owner, private  # ``private``: repos this remote creates
        self.api = HfApi(token=token)

    @classmethod
    def from_remote(cls, remote: str | None = None, token: str | None = None, private: bool = False) -> HubRemote:
        """``remote`` (``hf://<owner>``), else ``$MOLMO_DATASETS_REMOTE``."""
        remote = remote or os.environ.get("MOLMO_DATASETS_REMOTE")
        if not remote:
            raise NamespaceError("no remote: set MOLMO_DATASETS_REMOTE=hf://<user or org> (or pass the remote)")
        kind, _, owner = remote.partition("://")
        if kind != "hf" or not owner or "/" in owner:
            raise NamespaceError(f"remote {remote!r}: expected hf://<user or org>")
        return cls(owner, token, private)

    def _repo(self, ident: str) -> tuple[str, str]:
        top, rest = _decompose(ident)
        return f"{self.owner}/{top}", rest

    def _read_json(self, repo_id: str, filename: str) -> dict[str, Any] | None:
        from huggingface_hub.errors import EntryNotFoundError, RepositoryNotFoundError

        try:
            path = self.api.hf_hub_download(repo_id=repo_id, filename=filename, repo_type="dataset")
        except (EntryNotFoundError, RepositoryNotFoundError):
            return None
        return json.loads(Path(path).read_text())

    def _registered(self, repo_id: str, key: str, ident: str) -> bytes:
        """The repo's root namespace metadata with ``ident`` added to its ``key`` list."""
        root = self._read_json(repo_id, NAMESPACE_METADATA_FILENAME) or {}
        root[key] = sorted(set(root.get(key, [])) | {ident})
        return _dump(root).encode()

    def list_namespaces(self) -> list[str]:
        """Every namespace on the Hub: each repo with a root ``namespace_metadata.json`` and those it registers."""
        out: list[str] = []
        for info in self.api.list_datasets(author=self.owner):
            metadata = self._read_json(info.id, NAMESPACE_METADATA_FILENAME)
            if metadata is not None:
                out += [info.id.split("/", 1)[1], *metadata.get("namespaces", [])]
        return out

    def list_datasets(self, prefix: str | None = None) -> list[str]:
        """Every dataset on the Hub: those each namespace repo registers, and repos that are a dataset."""
        out: list[str] = []
        for info in self.api.list_datasets(author=self.owner):
            name = info.id.split("/", 1)[1]
            metadata = self._read_json(info.id, NAMESPACE_METADATA_FILENAME)
            if metadata is not None:
                out += metadata.get("datasets", [])
            elif self._read_json(info.id, "meta/info.json") is not None:
                out.append(name)
        return sorted(d for d in out if prefix is None or d == prefix or d.startswith(prefix.rstrip("/") + "/"))

    def upload_namespace(self, namespace: str, store: DatasetStore) -> None:
        """One commit: the namespace's metadata file, and for a nested one its registration in the repo root."""
        from huggingface_hub import CommitOperationAdd

        repo_id, path_in_repo = self._repo(namespace)
        self.api.create_repo(repo_id, repo_type="dataset", private=self.private, exist_ok=True)
        local = (store.path(namespace) / NAMESPACE_METADATA_FILENAME).read_bytes()
        ops = []
        if path_in_repo:
            registered = self._registered(repo_id, "namespaces", namespace)
            ops.append(CommitOperationAdd(NAMESPACE_METADATA_FILENAME, registered))
        ops.append(CommitOperationAdd(_join(path_in_repo, NAMESPACE_METADATA_FILENAME), local))
        self.api.create_commit(repo_id, ops, repo_type="dataset", commit_message=f"namespace {namespace}")

    def upload_dataset(self, dataset_id: str, store: DatasetStore) -> None:
        """One commit: the dataset's files under its folder (files of an earlier upload that it no longer has
        deleted) and its registration in the repo root; then LeRobot's codebase-version tag on that commit."""
        from huggingface_hub import CommitOperationAdd, CommitOperationDelete
        from huggingface_hub.errors import RevisionNotFoundError
        from lerobot.datasets.dataset_metadata import CODEBASE_VERSION

        repo_id, path_in_repo = self._repo(dataset_id)
        source = store.path(dataset_id)
        self.api.create_repo(repo_id, repo_type="dataset", private=self.private, exist_ok=True)
        ops: list[CommitOperationAdd | CommitOperationDelete] = [
               CommitOperationAdd(_join(path_in_repo, rel), str(source / rel))
               for rel, entry in sorted(fileio.walk(source).items())
               if entry[0] == "f" and not any(p.startswith(".") for p in rel.split("/"))]
        new = {op.path_in_repo for op in ops}
        prefix = f"{path_in_repo}/" if path_in_repo else ""
        ops += [CommitOperationDelete(path) for path in self.api.list_repo_files(repo_id, repo_type="dataset")
                if path.startswith(prefix) and path not in new and not path.startswith(".")
                and not (not path_in_repo and path.endswith(NAMESPACE_METADATA_FILENAME))]
        if path_in_repo and self._read_json(repo_id, NAMESPACE_METADATA_FILENAME) is not None:
            registered = self._registered(repo_id, "datasets", dataset_id)
            ops.append(CommitOperationAdd(NAMESPACE_METADATA_FILENAME, registered))
        commit = self.api.create_commit(repo_id, ops, repo_type="dataset", commit_message=f"dataset {dataset_id}")
        with contextlib.suppress(RevisionNotFoundError):
            self.api.delete_tag(repo_id, tag=CODEBASE_VERSION, repo_type="dataset")
        self.api.create_tag(repo_id, tag=CODEBASE_VERSION, revision=commit.oid, repo_type="dataset")

    def download_namespace_metadata(self, namespace: str, store: DatasetStore) -> None:
        repo_id, path_in_repo = self._repo(namespace)
        data = self._read_json(repo_id, _join(path_in_repo, NAMESPACE_METADATA_FILENAME))
        if data is None:
            raise NamespaceError(f"namespace {namespace!r} has no {NAMESPACE_METADATA_FILENAME} in {repo_id} "
                                 "on the Hub")
        store._write(f"{namespace}/{NAMESPACE_METADATA_FILENAME}", _dump(data))

    def download_dataset(self, dataset_id: str, store: DatasetStore) -> Path:
        """Download into a hidden directory of the store, then rename into place (all or nothing)."""
        repo_id, path_in_repo = self._repo(dataset_id)
        staging = fileio.make_dirs(store.root / f".incoming-{uuid.uuid4().hex}", root=store.root)
        try:
            self.api.snapshot_download(repo_id=repo_id, repo_type="dataset", local_dir=staging / "repo",
                                       allow_patterns=_join(path_in_repo, "*") if path_in_repo else None)
            got = staging / "repo" / path_in_repo
            fileio.rmtree(got / ".cache", root=staging)
            if not is_dataset_dir(got):
                raise NamespaceError(f"dataset {dataset_id!r} is not on the Hub ({repo_id} has no "
                                     f"{_join(path_in_repo, 'meta/info.json')})")
            fileio.replace(got, store.path(dataset_id), root=store.root)
        finally:
            fileio.rmtree(staging, root=store.root, ignore_errors=True)
        return store.path(dataset_id)


# -- Minari's module-level API on the default store and remote -----------------------------------
def create_namespace(namespace: str, description: str | None = None, **kwargs: Any) -> None:
    """Create a local namespace (Minari's ``create_namespace``)."""
    DatasetStore().create_namespace(namespace, description, **kwargs)


def update_namespace_metadata(namespace: str, description: str | None = None, **kwargs: Any) -> None:
    """Overwrite an existing local namespace's metadata."""
    DatasetStore().update_namespace_metadata(namespace, description, **kwargs)


def get_namespace_metadata(namespace: str) -> dict[str, Any]:
    """A local namespace's metadata."""
    return DatasetStore().get_namespace_metadata(namespace)


def delete_namespace(namespace: str) -> None:
    """Delete an empty local namespace."""
    DatasetStore().delete_namespace(namespace)


def list_local_namespaces() -> list[str]:
    """The local namespaces, sorted."""
    return DatasetStore().list_local_namespaces()


def list_local_datasets(prefix: str | None = None) -> dict[str, dict[str, Any]]:
    """The local datasets and their dataset-level metadata."""
    return DatasetStore().list_local_datasets(prefix)


def list_remote_namespaces(remote: str | None = None) -> list[str]:
    """The namespaces on the Hub (``remote`` or ``$MOLMO_DATASETS_REMOTE``)."""
    return list(HubRemote.from_remote(remote).list_namespaces())


def list_remote_datasets(prefix: str | None = None, remote: str | None = None) -> list[str]:
    """The dataset ids on the Hub."""
    return HubRemote.from_remote(remote).list_datasets(prefix)


def download_namespace_metadata(namespace: str, overwrite: bool = False, *, store: DatasetStore | None = None,
                                remote: str | None = None) -> None:
    """Fetch a remote namespace's metadata into the local store (an existing local one is kept, with a
    warning, unless ``overwrite``)."""
    validate_namespace(namespace)
    store = store or DatasetStore()
    if not overwrite and store.is_namespace(namespace):
        warnings.warn(f"skipping namespace {namespace!r}: it exists locally in {store.root} (overwrite=True "
                      "replaces its metadata)", UserWarning, stacklevel=2)
        return
    hub = HubRemote.from_remote(remote)
    if namespace not in hub.list_namespaces():
        raise NamespaceError(f"namespace {namespace!r} is not on the Hub (hf://{hub.owner})")
    hub.download_namespace_metadata(namespace, store)


def upload_namespace(namespace: str, token: str | None = None, *, store: DatasetStore | None = None,
                     remote: str | None = None) -> None:
    """Upload a local namespace and its local parents missing from the Hub, parents first (one already on
    the Hub warns and uploads nothing, as Minari)."""
    validate_namespace(namespace)
    store = store or DatasetStore()
    hub = HubRemote.from_remote(remote, token)
    if not store.is_namespace(namespace):
        raise NamespaceError(f"namespace {namespace!r} does not exist in {store.root}")
    remote_namespaces = set(hub.list_namespaces())
    if namespace in remote_namespaces:
        warnings.warn(f"upload of namespace {namespace!r} skipped: it is already on the Hub (hf://{hub.owner})",
                      UserWarning, stacklevel=2)
        return
    for parent in namespace_hierarchy(namespace):
        if store.is_namespace(parent) and parent not in remote_namespaces:
            hub.upload_namespace(parent, store)


def upload_dataset(dataset_id: str, token: str | None = None, *, store: DatasetStore | None = None,
                   remote: str | None = None, private: bool = False) -> None:
    """Upload a stored dataset: its namespace chain first (as :func:`upload_namespace`), then the dataset.
    A dataset id already on the Hub is uploaded again (a resumed run's new recording replaces it)."""
    store = store or DatasetStore()
    if not store.is_dataset(dataset_id):
        raise NamespaceError(f"dataset {dataset_id!r} is not in {store.root}")
    namespace, _ = parse_dataset_id(dataset_id)
    hub = HubRemote.from_remote(remote, token, private)  # ``private``: the repo, if this creates it
    if namespace is not None:
        remote_namespaces = set(hub.list_namespaces())
        for parent in namespace_hierarchy(namespace):
            if store.is_namespace(parent) and parent not in remote_namespaces:
                hub.upload_namespace(parent, store)
    hub.upload_dataset(dataset_id, store)


def download_dataset(dataset_id: str, force_download: bool = False, *, store: DatasetStore | None = None,
                     remote: str | None = None) -> Path:
    """Fetch a dataset from the Hub into the store, with the metadata of its namespaces missing locally; a
    dataset already stored is kept (with a warning) unless ``force_download``."""
    store = store or DatasetStore()
    namespace, _ = parse_dataset_id(dataset_id)
    if store.is_dataset(dataset_id):
        if not force_download:
            warnings.warn(f"skipping download: dataset {dataset_id!r} is in {store.root} (force_download=True "
                          "fetches it again)", UserWarning, stacklevel=2)
            return store.path(dataset_id)
        store.delete_dataset(dataset_id)
    else:
        store.check_new_dataset(dataset_id)
    hub = HubRemote.from_remote(remote)
    if namespace is not None and not store.is_namespace(namespace):
        for parent in namespace_hierarchy(namespace):
            if not store.is_namespace(parent):
                hub.download_namespace_metadata(parent, store)
    return hub.download_dataset(dataset_id, store)


def resolve_run(ident: str | os.PathLike) -> Path:
    """A run directory given as itself or as the dataset id of its recording in the store."""
    if os.path.isdir(ident) or not isinstance(ident, str):
        return Path(ident)
    try:
        parse_dataset_id(ident)
    except NamespaceError:
        return Path(ident)
    store = DatasetStore()
    return store.run_dir(ident) if store.is_dataset(ident) else Path(ident)

