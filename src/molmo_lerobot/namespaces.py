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
accepts and then cannot find again) or a part longer than a file name can be is refused, and a
namespace never goes inside or over a dataset (Minari writes its metadata file into the dataset's
directory).

A LeRobot dataset is a directory holding ``meta/info.json`` (Minari's marker is ``data/``); the
namespace listing never descends into one. Every error is one line naming the id
(:class:`NamespaceError`); every write goes through :mod:`molmo_lerobot.fileio`, and no store
operation goes through a symbolic link or opens a file that is not a regular one. Which local run
directory recorded a dataset (``resume`` and ``molmo-compare`` by dataset id) is recorded in the
store's hidden ``.run_dirs/``, bound to that dataset's directory, where no pull writes.

The Hub (:class:`HubRemote`, a remote ``hf://<user or org>``, ``$MOLMO_DATASETS_REMOTE``) maps
namespaces as Minari's Hugging Face storage does: the top-level namespace ``ns`` is the dataset
repo ``<owner>/ns``; nested namespaces and datasets are folders in it (``sub/``,
``sub/name/``), each namespace folder with its ``namespace_metadata.json``; the repo's root
``namespace_metadata.json`` also registers every nested namespace (``namespaces``) and dataset
(``datasets``) uploaded into it, which is what :func:`list_remote_namespaces` reads.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import posixpath
import re
import shutil
import stat
import time
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
#: local only: ``<root>/.run_dirs/<dataset id>.json`` says which run directory recorded the dataset
RUN_DIRS = ".run_dirs"
#: hidden directories of the store that a copy or a pull is built in
STAGING_PREFIX = ".incoming-"
#: a staging directory that no process holds (``flock``) and nothing touched for this long is a
#: killed process's leftover, swept by the next copy or pull
STALE_STAGING_S = 3600.0
_NAME_RE = re.compile(r"[-_\w][-_.\w]*")
#: the longest id part (a file name) in bytes: NAME_MAX of the common filesystems
_PART_MAX = 255
#: room kept below the filesystem's path limit for the files inside a dataset and temporary names
_ROOM = 256


class NamespaceError(MolmoError, ValueError):
    """An invalid, missing, existing or non-empty namespace or dataset; the one-line message names it."""


class NamespaceTypeError(NamespaceError, TypeError):
    """No namespace given (``None``), as Minari's ``TypeError``."""


# -- ids ----------------------------------------------------------------------------------------
def shown(ident: object) -> str:
    """``ident`` quoted for a one-line message: control characters escaped, a long one shortened."""
    if not isinstance(ident, str) or len(ident) <= 80:
        return repr(ident)
    return f"{ident[:60]!r}… ({len(ident)} characters)"


def _check_parts(ident: str, what: str) -> None:
    """Raise when a part of ``ident`` is longer than a file name can be."""
    longest = max(ident.split("/"), key=lambda part: len(part.encode()))
    if len(longest.encode()) > _PART_MAX:
        raise NamespaceError(f"{what} {shown(ident)} is too long: its part {shown(longest)} has "
                             f"{len(longest.encode())} bytes, and a file name at most {_PART_MAX}")


def validate_namespace(namespace: str | None) -> None:
    """Raise unless ``namespace`` is a namespace id: Minari's ``[-_\\w][-_\\w/]*[-_\\w]+`` with no empty part,
    and no part longer than a file name."""
    if namespace is None:
        raise NamespaceTypeError("namespace cannot be None")
    if not isinstance(namespace, str) or not NAMESPACE_REGEX.fullmatch(namespace) or "//" in namespace:
        raise NamespaceError(f"malformed namespace {shown(namespace)}: use letters, digits, '-', '_' and '/' between "
                             "parts (at least 2 characters, no leading, trailing or double '/')")
    _check_parts(namespace, "namespace")


def parse_dataset_id(dataset_id: str) -> tuple[str | None, str]:
    """Split ``ns/sub/name`` into ``("ns/sub", "name")``; ``name`` alone has no namespace."""
    if not isinstance(dataset_id, str) or not dataset_id:
        raise NamespaceError(f"malformed dataset id {shown(dataset_id)}: expected [namespace/]name")
    namespace, _, name = dataset_id.rpartition("/")
    if not _NAME_RE.fullmatch(name):
        raise NamespaceError(f"malformed dataset id {shown(dataset_id)}: the name {shown(name)} must start with a "
                             "letter, digit, '-' or '_' and use only those and '.'")
    _check_parts(dataset_id, "dataset id")
    if namespace or dataset_id.startswith("/"):
        try:
            validate_namespace(namespace)
        except NamespaceError as exc:
            raise NamespaceError(f"malformed dataset id {shown(dataset_id)}: {exc}") from None
    return namespace or None, name


def namespace_hierarchy(namespace: str | None) -> Iterator[str]:
    """``a``, ``a/b``, ``a/b/c`` for ``a/b/c``: the namespace's parents, then itself (Minari's order)."""
    if namespace is None:
        return
    parts = namespace.split("/")
    for i in range(len(parts)):
        yield posixpath.join(*parts[: i + 1])  # as Minari's os.path.join (``/ab`` gives ``""``, ``ab``)


def is_dataset_dir(path: Path) -> bool:
    """Whether ``path`` is a LeRobot dataset: a directory holding the regular file ``meta/info.json``,
    none of the three a link."""
    path = Path(path)
    return _is(path, stat.S_ISDIR) and _is(path / "meta", stat.S_ISDIR) and _is(path / "meta" / "info.json",
                                                                              stat.S_ISREG)


def _is(path: Path, kind: Any) -> bool:
    """Whether ``path`` itself (not what a link there points to) is of ``kind`` (``stat.S_ISDIR`` …)."""
    try:
        return bool(kind(os.lstat(path).st_mode))
    except (OSError, ValueError):  # missing, a part not a directory, too long; a NUL byte
        return False


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

    def _read(self, ident: str, name: str, what: str) -> bytes:
        """The file ``name`` of the namespace or dataset ``ident``, read without going through a link or
        opening a file that is not a regular one; ``FileNotFoundError`` when it is missing."""
        try:
            return fileio.read_bytes(self.path(ident) / name, root=self.root)
        except FileNotFoundError:
            raise
        except OSError as exc:
            raise NamespaceError(f"{what} {shown(ident)}: {exc}".splitlines()[0]) from None

    def _path_problem(self, ident: str) -> str | None:
        """What makes the path ``ident`` below the root unusable, if anything: a part that is a symbolic link,
        one before the last that is not a directory, a last one that is neither a directory nor a regular
        file (the store never goes through a link nor opens a FIFO)."""
        path, parts = self.root, ident.split("/")
        for i, part in enumerate(parts):
            path = path / part
            try:
                mode = os.lstat(path).st_mode
            except FileNotFoundError:
                return None
            except (OSError, ValueError) as exc:
                return f"{shown(str(path))} cannot be looked up ({exc})"
            if stat.S_ISLNK(mode):
                return f"{path} is a symlink; the store never goes through one"
            if i < len(parts) - 1 and not stat.S_ISDIR(mode):
                return f"{path} is not a directory"
            if not (stat.S_ISDIR(mode) or stat.S_ISREG(mode)):
                return f"{path} is not a regular file or a directory"
        return None

    def _check_path(self, ident: str, what: str) -> None:
        """Raise unless the store's filesystem can hold ``ident`` (each part a file name, the whole path with
        room for a dataset's files) and its path goes through no link."""
        probe = self.root
        while not os.path.isdir(probe) and probe.parent != probe:
            probe = probe.parent
        name_max, path_max = _pathconf(probe, "PC_NAME_MAX", _PART_MAX), _pathconf(probe, "PC_PATH_MAX", 4096)
        longest = max(len(os.fsencode(part)) for part in ident.split("/"))
        if longest > name_max or len(os.fsencode(self.path(ident))) + _ROOM > path_max:
            room = path_max - _ROOM - len(os.fsencode(self.root)) - 1
            raise NamespaceError(f"{what} {shown(ident)} is too long for the store {self.root} (at most {name_max} "
                                 f"bytes a part and {max(room, 0)} in all)")
        problem = self._path_problem(ident)
        if problem is not None:
            raise NamespaceError(f"{what} {shown(ident)}: {problem}")

    def _inside_dataset(self, ident: str) -> str | None:
        """The stored dataset that ``ident`` is, or lies inside of, if any."""
        for parent in namespace_hierarchy(ident):
            if is_dataset_dir(self.path(parent)):
                return parent
        return None

    def is_namespace(self, namespace: str) -> bool:
        metadata = self.path(namespace) / NAMESPACE_METADATA_FILENAME
        return (_is(metadata, stat.S_ISREG) and self._path_problem(namespace) is None
                and self._inside_dataset(namespace) is None)

    def is_dataset(self, dataset_id: str) -> bool:
        parse_dataset_id(dataset_id)
        return self._path_problem(dataset_id) is None and is_dataset_dir(self.path(dataset_id))

    # Minari's namespace functions ---------------------------------------------------------------
    def create_namespace(self, namespace: str, description: str | None = None, **kwargs: Any) -> None:
        """Create ``namespace`` (its missing parents too, with empty metadata); an existing one is an error."""
        validate_namespace(namespace)
        if self.is_namespace(namespace):
            raise NamespaceError(f"namespace {shown(namespace)} already exists in {self.root}")
        self._check_path(namespace, "namespace")
        inside = self._inside_dataset(namespace)
        if inside is not None:
            raise NamespaceError(f"namespace {shown(namespace)} collides with the dataset {shown(inside)} in "
                                 f"{self.root}")
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
        self._existing(namespace)
        try:
            return json.loads(self.namespace_metadata_bytes(namespace))
        except ValueError as exc:
            raise NamespaceError(f"namespace {shown(namespace)}: {self.path(namespace) / NAMESPACE_METADATA_FILENAME}"
                                 f" is not valid JSON ({exc})") from None

    def namespace_metadata_bytes(self, namespace: str) -> bytes:
        """The ``namespace_metadata.json`` of an existing namespace, as stored."""
        try:
            return self._read(namespace, NAMESPACE_METADATA_FILENAME, "namespace")
        except FileNotFoundError:
            raise NamespaceError(f"namespace {shown(namespace)} does not exist in {self.root}") from None

    def delete_namespace(self, namespace: str) -> None:
        """Delete the empty ``namespace`` (a missing one warns, as Minari); one holding anything is an error."""
        validate_namespace(namespace)
        if not self.is_namespace(namespace):
            warnings.warn(f"namespace {shown(namespace)} does not exist in {self.root}", UserWarning, stacklevel=2)
            return
        directory = self.path(namespace)
        contents = sorted(os.listdir(directory))
        others = [name for name in contents if name != NAMESPACE_METADATA_FILENAME]
        if others:
            held = ", ".join(others[:5]) + (f" and {len(others) - 5} more" if len(others) > 5 else "")
            raise NamespaceError(f"namespace {shown(namespace)} is not empty (it holds {held}); delete its datasets "
                                 "and namespaces first")
        fileio.rmtree(directory, root=self.root)  # empty but for its metadata file

    def list_local_namespaces(self) -> list[str]:
        """Every namespace in the store, sorted; never looks inside a dataset or a hidden directory."""
        return sorted(ident for ident, kind in self._walk() if kind == "namespace")

    def list_local_datasets(self, prefix: str | None = None) -> dict[str, dict[str, Any]]:
        """``{dataset_id: dataset-level metadata}`` of every stored dataset (under ``prefix``), sorted; a
        dataset whose metadata cannot be read is listed with ``{}`` and a warning saying why."""
        out = {}
        for ident, kind in sorted(self._walk()):
            if kind == "dataset" and (prefix is None or ident == prefix or ident.startswith(prefix.rstrip("/") + "/")):
                try:
                    out[ident] = self.dataset_metadata(ident)
                except NamespaceError as exc:
                    warnings.warn(str(exc), UserWarning, stacklevel=2)
                    out[ident] = {}
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
                    if _is(Path(entry.path) / NAMESPACE_METADATA_FILENAME, stat.S_ISREG):
                        yield ident, "namespace"
                    yield from recurse(ident)
        yield from recurse("")

    def _existing(self, namespace: str) -> Path:
        validate_namespace(namespace)
        if not self.is_namespace(namespace):
            problem = self._path_problem(f"{namespace}/{NAMESPACE_METADATA_FILENAME}")
            raise NamespaceError(f"namespace {shown(namespace)} " + (
                f"cannot be used: {problem}" if problem else f"does not exist in {self.root}"))
        return self.path(namespace)

    # datasets -----------------------------------------------------------------------------------
    def existing_dataset(self, dataset_id: str) -> Path:
        """The path of the stored dataset ``dataset_id``; one line saying why when it is not there or its path
        goes through a link."""
        if not self.is_dataset(dataset_id):
            problem = self._path_problem(dataset_id)
            raise NamespaceError(f"dataset {shown(dataset_id)} " + (
                f"cannot be used: {problem}" if problem else f"is not in {self.root}"))
        return self.path(dataset_id)

    def dataset_metadata(self, dataset_id: str) -> dict[str, Any]:
        """A stored dataset's dataset-level metadata (``{}`` when it has none); one that is not a JSON
        object in a regular file is a :class:`NamespaceError`."""
        return self._dataset_json(dataset_id, DATASET_METADATA_FILE) or {}

    def dataset_info(self, dataset_id: str) -> dict[str, Any]:
        """A stored dataset's LeRobot ``meta/info.json``."""
        self.existing_dataset(dataset_id)
        return self._dataset_json(dataset_id, "meta/info.json") or {}

    def _dataset_json(self, dataset_id: str, name: str) -> dict[str, Any] | None:
        try:
            data = json.loads(self._read(dataset_id, name, "dataset"))
        except FileNotFoundError:
            return None
        except ValueError as exc:
            raise NamespaceError(f"dataset {shown(dataset_id)}: {self.path(dataset_id) / name} is not valid JSON "
                                 f"({exc})") from None
        if not isinstance(data, dict):
            raise NamespaceError(f"dataset {shown(dataset_id)}: {self.path(dataset_id) / name} is not a JSON object")
        return data

    def dataset_files(self, dataset_id: str) -> list[str]:
        """The files of a stored dataset that a push uploads (never its hidden ones), relative to it, sorted;
        a link or a file that is not a regular one in it is refused, as is a link on the way to it."""
        source = self.existing_dataset(dataset_id)
        files = []
        for rel, entry in sorted(fileio.walk(source).items()):
            if any(part.startswith(".") for part in rel.split("/")):
                continue
            if entry[0] in ("l", "o"):
                raise NamespaceError(f"dataset {shown(dataset_id)}: {source / rel} is "
                                     f"{'a symlink' if entry[0] == 'l' else 'not a regular file'}; refusing to read it")
            if entry[0] == "f":
                files.append(rel)
        return files

    def run_dir(self, dataset_id: str) -> Path:
        """The run directory that recorded a stored dataset into this store (for ``resume`` and
        ``molmo-compare``); a dataset pulled or copied in names none."""
        self.existing_dataset(dataset_id)
        recorded = self._recorded_run_dir(dataset_id)
        if recorded is None:
            raise NamespaceError(f"dataset {shown(dataset_id)} in {self.root} was not recorded into this store by "
                                 "molmo-eval (a pulled or copied dataset names no run directory here)")
        return Path(recorded)

    def _run_record(self, dataset_id: str) -> str:
        return f"{RUN_DIRS}/{dataset_id}.json"

    def _recorded_run_dir(self, dataset_id: str) -> str | None:
        """The run directory recorded for ``dataset_id``, if the record is for the directory now there
        (the same device and inode: a dataset replaced since, by a pull or by hand, has none)."""
        try:
            record = json.loads(fileio.read_bytes(self.root / self._run_record(dataset_id), root=self.root))
            here = os.lstat(self.path(dataset_id))
        except (OSError, ValueError):
            return None
        if not isinstance(record, dict) or record.get("dataset") != [here.st_dev, here.st_ino]:
            return None
        run_dir = record.get("run_dir")
        return run_dir if isinstance(run_dir, str) else None

    def check_new_dataset(self, dataset_id: str, run_dir: str | os.PathLike | None = None) -> None:
        """Raise unless ``dataset_id`` can be stored: a valid id that the store's filesystem can hold, whose
        path goes through no link, whose place is free (or holds the recording of ``run_dir``, which a resume
        replaces) and lies in no other dataset."""
        namespace, _ = parse_dataset_id(dataset_id)
        self._check_path(dataset_id, "dataset id")
        inside = self._inside_dataset(namespace) if namespace else None
        if inside is not None:
            raise NamespaceError(f"dataset id {shown(dataset_id)} lies inside the dataset {shown(inside)} in "
                                 f"{self.root}")
        path = self.path(dataset_id)
        if not os.path.lexists(path):
            return
        if is_dataset_dir(path):
            mine = run_dir is not None and _same_dir(self._recorded_run_dir(dataset_id), run_dir)
            if not mine:
                raise NamespaceError(f"dataset id {shown(dataset_id)} collides with an existing dataset in "
                                     f"{self.root} (pick another id, or delete that dataset first)")
        elif _is(path / NAMESPACE_METADATA_FILENAME, stat.S_ISREG):
            raise NamespaceError(f"dataset id {shown(dataset_id)} collides with the namespace {shown(dataset_id)} in "
                                 f"{self.root}")
        else:
            raise NamespaceError(f"dataset id {shown(dataset_id)}: {path} exists and is not a dataset; move it away "
                                 "first")

    @contextlib.contextmanager
    def staging(self) -> Iterator[Path]:
        """A new hidden directory of the store to build a dataset in, locked (``flock``) while in use and
        removed after; first, the leftovers of killed processes are swept (:data:`STALE_STAGING_S`)."""
        self._sweep_staging()
        path = fileio.make_dirs(self.root / f"{STAGING_PREFIX}{uuid.uuid4().hex}", root=self.root)
        try:
            with fileio.open_dir(path, root=self.root, create=False) as fd:
                fcntl.flock(fd, fcntl.LOCK_EX)
                yield path
        finally:
            fileio.rmtree(path, root=self.root, ignore_errors=True)

    def _sweep_staging(self) -> None:
        """Remove the staging directories that no process holds and nothing touched for :data:`STALE_STAGING_S`."""
        try:
            with os.scandir(self.root) as it:
                names = [e.name for e in it if e.name.startswith(STAGING_PREFIX) and e.is_dir(follow_symlinks=False)]
        except (FileNotFoundError, NotADirectoryError):
            return
        for name in names:
            with contextlib.suppress(OSError), fileio.open_dir(self.root / name, root=self.root, create=False) as fd:
                if time.time() - os.fstat(fd).st_mtime < STALE_STAGING_S:
                    continue
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # BlockingIOError (an OSError): in use
                fileio.rmtree(self.root / name, root=self.root)

    def add_dataset(self, dataset_id: str, source: str | os.PathLike, metadata: dict[str, Any],
                    run_dir: str | os.PathLike | None = None) -> Path:
        """Copy the LeRobot dataset at ``source`` into the store as ``dataset_id`` with its dataset-level
        ``metadata``; missing namespaces are created as Minari creates them (empty metadata). The copy is
        built in a hidden directory of the store and renamed into place, so the store holds the whole
        dataset or none of it; the recording of ``run_dir`` already stored there (a resume) is replaced,
        and ``run_dir`` is recorded as the run directory of the new one."""
        source = Path(source)
        self.check_new_dataset(dataset_id, run_dir)
        odd = [(rel, entry[0]) for rel, entry in fileio.walk(source).items() if entry[0] in ("l", "o")]
        if odd:
            rel, kind = odd[0]
            raise NamespaceError(f"dataset {shown(dataset_id)}: {source / rel} is "
                                 f"{'a symlink' if kind == 'l' else 'not a regular file'}; refusing to store it")
        if not is_dataset_dir(source):
            raise NamespaceError(f"dataset {shown(dataset_id)}: {source} is not a LeRobot dataset (no meta/info.json)")
        namespace, _ = parse_dataset_id(dataset_id)
        if namespace is not None and not self.is_namespace(namespace):
            self.create_namespace(namespace)
        with self.staging() as staging:
            shutil.copytree(source, staging / "dataset", ignore=shutil.ignore_patterns(".*", "images"))
            fileio.atomic_write(staging / "dataset" / DATASET_METADATA_FILE,
                                json.dumps({"dataset_id": dataset_id, **metadata}, indent=2, sort_keys=True),
                                root=staging)
            if run_dir is not None:  # bound to the directory renamed into place below
                built = os.lstat(staging / "dataset")
                self._write(self._run_record(dataset_id), json.dumps(
                    {"run_dir": str(Path(run_dir).resolve()), "dataset": [built.st_dev, built.st_ino]}))
            target = self.path(dataset_id)
            if is_dataset_dir(target):  # this run's earlier recording (check_new_dataset allowed it)
                fileio.replace(target, staging / "old", root=self.root)
            fileio.replace(staging / "dataset", target, root=self.root)
        return self.path(dataset_id)

    def delete_dataset(self, dataset_id: str) -> None:
        """Remove a stored dataset (its namespaces stay) and the record of its run directory."""
        fileio.rmtree(self.existing_dataset(dataset_id), root=self.root)
        fileio.remove(self.root / self._run_record(dataset_id), root=self.root)


def _pathconf(path: Path, name: str, default: int) -> int:
    try:
        return os.pathconf(path, name)
    except (OSError, ValueError):
        return default


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
        """The JSON object ``filename`` of the dataset repo ``repo_id`` (None when either is missing); a file
        that is not one is a :class:`NamespaceError`."""
        from huggingface_hub.errors import EntryNotFoundError, RepositoryNotFoundError

        try:
            path = self.api.hf_hub_download(repo_id=repo_id, filename=filename, repo_type="dataset")
        except (EntryNotFoundError, RepositoryNotFoundError):
            return None
        try:
            data = json.loads(Path(path).read_bytes())
        except ValueError as exc:
            raise NamespaceError(f"{shown(repo_id)} on the Hub: {filename} is not valid JSON ({exc})") from None
        if not isinstance(data, dict):
            raise NamespaceError(f"{shown(repo_id)} on the Hub: {filename} is not a JSON object")
        return data

    def _registered(self, repo_id: str, key: str, ident: str) -> bytes:
        """The repo's root namespace metadata with ``ident`` added to its ``key`` list."""
        root = self._read_json(repo_id, NAMESPACE_METADATA_FILENAME) or {}
        listed = root.get(key, [])
        if not isinstance(listed, list) or not all(isinstance(i, str) for i in listed):
            raise NamespaceError(f"{shown(repo_id)} on the Hub: {key!r} in its {NAMESPACE_METADATA_FILENAME} is not "
                                 "a list of ids")
        root[key] = sorted(set(listed) | {ident})
        return _dump(root).encode()

    def _repos(self) -> Iterator[tuple[str, str, dict[str, Any] | None]]:
        """``(repo id, repo name, its root namespace metadata or None)`` of each of the owner's dataset repos;
        a repo whose metadata is not a JSON object is skipped with a warning."""
        for info in self.api.list_datasets(author=self.owner):
            try:
                yield info.id, info.id.split("/", 1)[-1], self._read_json(info.id, NAMESPACE_METADATA_FILENAME)
            except NamespaceError as exc:
                warnings.warn(f"{exc}; skipped", UserWarning, stacklevel=3)

    def _listed(self, repo_id: str, top: str, idents: list[Any], check: Any) -> list[str]:
        """The ids of ``idents`` that are well formed (``check``) and lie in the repo's top namespace ``top``;
        each other one is skipped with a warning that shows it escaped."""
        out = []
        for ident in idents:
            try:
                if not isinstance(ident, str):
                    raise NamespaceError(f"{shown(ident)} is not an id")
                check(ident)
                if ident != top and not ident.startswith(f"{top}/"):
                    raise NamespaceError(f"{shown(ident)} is not in its namespace {shown(top)}")
            except NamespaceError as exc:
                warnings.warn(f"{shown(repo_id)} on the Hub registers a bad id: {exc}; skipped", UserWarning,
                              stacklevel=3)
                continue
            out.append(ident)
        return out

    def list_namespaces(self) -> list[str]:
        """Every namespace on the Hub: each repo with a root ``namespace_metadata.json`` and those it registers
        (a malformed one, or one outside the repo's namespace, is skipped with a warning)."""
        out: list[str] = []
        for repo_id, top, metadata in self._repos():
            if metadata is not None:
                nested = metadata.get("namespaces", [])
                out += self._listed(repo_id, top, [top, *(nested if isinstance(nested, list) else [nested])],
                                    validate_namespace)
        return out

    def list_datasets(self, prefix: str | None = None) -> list[str]:
        """Every dataset on the Hub: those each namespace repo registers, and repos that are a dataset (a
        malformed id, or one outside the repo's namespace, is skipped with a warning)."""
        out: list[str] = []
        for repo_id, name, metadata in self._repos():
            if metadata is not None:
                listed = metadata.get("datasets", [])
                out += self._listed(repo_id, name, listed if isinstance(listed, list) else [listed], parse_dataset_id)
            elif self._read_json(repo_id, "meta/info.json") is not None:
                out += self._listed(repo_id, name, [name], parse_dataset_id)
        return sorted(d for d in out if prefix is None or d == prefix or d.startswith(prefix.rstrip("/") + "/"))

    def upload_namespace(self, namespace: str, store: DatasetStore) -> None:
        """One commit: the namespace's metadata file, and for a nested one its registration in the repo root."""
        from huggingface_hub import CommitOperationAdd

        repo_id, path_in_repo = self._repo(namespace)
        self.api.create_repo(repo_id, repo_type="dataset", private=self.private, exist_ok=True)
        local = store.namespace_metadata_bytes(namespace)
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
        source, files = store.path(dataset_id), store.dataset_files(dataset_id)
        self.api.create_repo(repo_id, repo_type="dataset", private=self.private, exist_ok=True)
        ops: list[CommitOperationAdd | CommitOperationDelete] = [
               CommitOperationAdd(_join(path_in_repo, rel), str(source / rel)) for rel in files]
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
            raise NamespaceError(f"namespace {shown(namespace)} has no {NAMESPACE_METADATA_FILENAME} in {repo_id} "
                                 "on the Hub")
        store._write(f"{namespace}/{NAMESPACE_METADATA_FILENAME}", _dump(data))

    def download_dataset(self, dataset_id: str, store: DatasetStore) -> Path:
        """Download into a hidden directory of the store, then rename into place (all or nothing). The
        dataset's hidden files are not kept (nothing local is decided by a pulled file), and a link or a
        file that is not a regular one in it is refused."""
        repo_id, path_in_repo = self._repo(dataset_id)
        with store.staging() as staging:
            self.api.snapshot_download(repo_id=repo_id, repo_type="dataset", local_dir=staging / "repo",
                                       allow_patterns=_join(path_in_repo, "*") if path_in_repo else None)
            got = staging / "repo" / path_in_repo
            for rel in [rel for rel in fileio.walk(got) if rel.rpartition("/")[2].startswith(".")]:
                fileio.rmtree(got / rel, root=staging)  # a hidden folder's contents go with it
            odd = sorted(rel for rel, entry in fileio.walk(got).items() if entry[0] in ("l", "o"))
            if odd:
                raise NamespaceError(f"dataset {shown(dataset_id)} from {repo_id}: {shown(odd[0])} is not a regular "
                                     "file; refusing it")
            if not is_dataset_dir(got):
                raise NamespaceError(f"dataset {shown(dataset_id)} is not on the Hub ({repo_id} has no "
                                     f"{_join(path_in_repo, 'meta/info.json')})")
            fileio.replace(got, store.path(dataset_id), root=store.root)
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
        warnings.warn(f"skipping namespace {shown(namespace)}: it exists locally in {store.root} (overwrite=True "
                      "replaces its metadata)", UserWarning, stacklevel=2)
        return
    store._check_path(namespace, "namespace")
    hub = HubRemote.from_remote(remote)
    if namespace not in hub.list_namespaces():
        raise NamespaceError(f"namespace {shown(namespace)} is not on the Hub (hf://{hub.owner})")
    hub.download_namespace_metadata(namespace, store)


def upload_namespace(namespace: str, token: str | None = None, *, store: DatasetStore | None = None,
                     remote: str | None = None) -> None:
    """Upload a local namespace and its local parents missing from the Hub, parents first (one already on
    the Hub warns and uploads nothing, as Minari)."""
    validate_namespace(namespace)
    store = store or DatasetStore()
    hub = HubRemote.from_remote(remote, token)
    store._existing(namespace)
    remote_namespaces = set(hub.list_namespaces())
    if namespace in remote_namespaces:
        warnings.warn(f"upload of namespace {shown(namespace)} skipped: it is already on the Hub (hf://{hub.owner})",
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
    store.dataset_files(dataset_id)  # a dataset that is not there, or holds a link, is refused before any upload
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
            warnings.warn(f"skipping download: dataset {shown(dataset_id)} is in {store.root} (force_download=True "
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

