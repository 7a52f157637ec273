"""Where resources live: a local directory (``file://``), a plain HTTP bucket (``https://``) or a
Hugging Face repo (``hf://``).

Two layouts below a remote's root, per ``<data_type>/<source>/<version>/``:

- ours (``molmo-resources pack``): ``manifest.json``, ``index.json.gz``, ``archives/<name>.tar.zst``;
- MolmoSpaces' (what their R2/GC buckets and HF dataset repo hold): an archive→size-in-MB
  manifest and an archive→path-trie index beside the archives themselves; on the Hub the
  archives are members of ``shards/NNNNN.tar`` files found through a ``pkgs`` parquet table
  (archive, shard, offset, size) in the repo dir ``<prefix>__<data_type>__<source>__<version>``,
  read with HTTP Range requests.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import uuid
from abc import ABC, abstractmethod
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote, unquote, urlparse

from molmo_lerobot import fileio
from molmo_lerobot.fileio import atomic_open, atomic_write
from molmo_lerobot.resources.errors import RemoteNotFoundError, ResourceError

if TYPE_CHECKING:
    import httpx

#: A version in MolmoSpaces' layout has this manifest ``format`` (ours: an integer).
MOLMOSPACES = "molmospaces"


class Remote(ABC):
    """A read/write store of files addressed by POSIX paths relative to its root."""

    url: str

    @abstractmethod
    def download(self, rel: str, dest: Path) -> None:
        """Copy the file ``rel`` to the local path ``dest`` (replacing it)."""

    @abstractmethod
    def upload_dir(self, local_dir: Path, rel_prefix: str, message: str = "") -> None:
        """Publish every file under ``local_dir`` below ``rel_prefix`` (all or nothing where possible)."""

    @abstractmethod
    def put_bytes(self, rel: str, data: bytes, message: str = "") -> None:
        """Write (or overwrite) one file."""

    @abstractmethod
    def list_files(self, prefix: str = "") -> list[str]:
        """Paths of every file below ``prefix`` (relative to the remote root)."""

    def fetch_archive(self, version_rel: str, name: str, dest: Path, layout: int | str) -> int | None:
        """Download one archive of a version to ``dest``; returns its unpacked size if the remote knows it."""
        self.download(f"{version_rel}/{name}" if layout == MOLMOSPACES else f"{version_rel}/archives/{name}", dest)
        return None

    def read_bytes(self, rel: str) -> bytes:
        with tempfile.TemporaryDirectory(prefix="molmo-remote-") as tmp:
            dest = Path(tmp) / "f"
            self.download(rel, dest)
            return dest.read_bytes()

    def exists(self, rel: str) -> bool:
        parent = rel.rsplit("/", 1)[0] if "/" in rel else ""
        return rel in self.list_files(parent)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.url!r})"


class LocalRemote(Remote):
    """A directory on a local or shared file system."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root).expanduser().resolve()
        self.url = self.root.as_uri()

    def _path(self, rel: str) -> Path:
        path = (self.root / rel).resolve()
        if not path.is_relative_to(self.root):
            raise ResourceError(f"remote {self.url}: path {rel!r} leaves the remote root")
        return path

    def download(self, rel: str, dest: Path) -> None:
        src = self._path(rel)
        if not src.is_file():
            raise RemoteNotFoundError(f"remote {self.url}: {rel} not found")
        with open(src, "rb") as fsrc, atomic_open(dest, "wb") as fdst:
            shutil.copyfileobj(fsrc, fdst)

    def upload_dir(self, local_dir: Path, rel_prefix: str, message: str = "") -> None:
        target = self._path(rel_prefix)
        if target.exists():
            raise ResourceError(f"remote {self.url}: {rel_prefix} already exists (versions are immutable)")
        fileio.make_dirs(target.parent, root=self.root)
        staging = target.parent / f".{target.name}.{uuid.uuid4().hex}.tmp"
        shutil.copytree(local_dir, staging)  # a new directory: copytree makes it, never through a link
        fileio.replace(staging, target, root=self.root)  # appears complete or not at all

    def put_bytes(self, rel: str, data: bytes, message: str = "") -> None:
        atomic_write(self._path(rel), data, root=self.root)

    def list_files(self, prefix: str = "") -> list[str]:
        base = self._path(prefix) if prefix else self.root
        if not base.is_dir():
            return []
        out: list[str] = []
        for dirpath, dirnames, filenames in os.walk(base):
            dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
            out.extend(Path(dirpath, f).relative_to(self.root).as_posix() for f in filenames)
        return sorted(out)


class HfRemote(Remote):
    """A Hugging Face repo (``hf://datasets/<ns>/<repo>[/<prefix>]``) through ``huggingface_hub``.

    The token comes from the environment (``HF_TOKEN`` or the stored login) and is never logged;
    the endpoint from ``HF_ENDPOINT`` unless given.
    """

    def __init__(self, repo_id: str, prefix: str = "", repo_type: str = "dataset", revision: str = "main",
                 endpoint: str | None = None) -> None:
        self.repo_id, self.prefix, self.repo_type, self.revision = repo_id, prefix.strip("/"), repo_type, revision
        self.endpoint = endpoint
        self._shards: dict[str, dict[str, dict]] = {}
        kind = {"dataset": "datasets/", "model": "models/"}[repo_type]
        self.url = f"hf://{kind}{repo_id}" + (f"/{self.prefix}" if self.prefix else "")

    def _api(self):
        from huggingface_hub import HfApi

        return HfApi(endpoint=self.endpoint)

    def _full(self, rel: str) -> str:
        return f"{self.prefix}/{rel}".strip("/") if self.prefix else rel

    def download(self, rel: str, dest: Path) -> None:
        from huggingface_hub import hf_hub_download
        from huggingface_hub.errors import (
            EntryNotFoundError,
            HfHubHTTPError,
            RepositoryNotFoundError,
            RevisionNotFoundError,
        )

        dest = Path(dest)
        with tempfile.TemporaryDirectory(prefix=".hf-", dir=dest.parent) as tmp:
            try:
                got = hf_hub_download(self.repo_id, self._full(rel), repo_type=self.repo_type, revision=self.revision,
                                      local_dir=tmp, endpoint=self.endpoint)
            except (EntryNotFoundError, RepositoryNotFoundError, RevisionNotFoundError) as exc:
                if (status := _status(exc)) in (401, 403):
                    raise ResourceError(_denied(self.url, rel, status)) from None
                raise RemoteNotFoundError(f"remote {self.url}: {rel} not found ({type(exc).__name__})") from None
            except HfHubHTTPError as exc:
                raise ResourceError(_http_failure(self.url, rel, _status(exc), exc)) from None
            fileio.replace(got, dest, root=dest.parent)

    def fetch_archive(self, version_rel: str, name: str, dest: Path, layout: int | str) -> int | None:
        """MolmoSpaces' layout: a Range read of the archive's bytes inside its shard."""
        if layout != MOLMOSPACES:
            return super().fetch_archive(version_rel, name, dest, layout)
        row = self.shard_index(version_rel).get(name)
        if row is None:
            raise ResourceError(f"remote {self.url}: archive {name} is not in the shard index of {version_rel}")
        shard = f"{version_rel}/shards/{row['shard_id']:05d}.tar"
        self.read_range(shard, row["offset"], row["size"], Path(dest), what=f"archive {name}")
        return row.get("inflated_size")

    def shard_index(self, version_rel: str) -> dict[str, dict]:
        """``{archive: {shard_id, offset, size[, inflated_size]}}`` from the version's ``pkgs`` parquet table."""
        if version_rel in self._shards:
            return self._shards[version_rel]
        import pyarrow.parquet as pq
        from huggingface_hub import hf_hub_download
        from huggingface_hub.errors import EntryNotFoundError, HfHubHTTPError

        folder = self._full(version_rel).replace("/", "__")
        try:
            tree = self._api().list_repo_tree(self.repo_id, path_in_repo=folder, repo_type=self.repo_type,
                                              revision=self.revision)
            tables = sorted(e.path for e in tree if e.path.endswith(".parquet") and "pkgs" in e.path.rsplit("/", 1)[-1])
        except EntryNotFoundError:
            tables = []
        except HfHubHTTPError as exc:
            raise ResourceError(_http_failure(self.url, folder, _status(exc), exc)) from None
        if not tables:
            raise RemoteNotFoundError(f"remote {self.url}: no shard index ({folder}/pkgs-*.parquet) for {version_rel}")
        rows: dict[str, dict] = {}
        with tempfile.TemporaryDirectory(prefix="molmo-shards-") as tmp:
            for table in tables:
                try:
                    local = hf_hub_download(self.repo_id, table, repo_type=self.repo_type, revision=self.revision,
                                            local_dir=tmp, endpoint=self.endpoint)
                    data = pq.read_table(local).to_pylist()
                except HfHubHTTPError as exc:
                    raise ResourceError(_http_failure(self.url, table, _status(exc), exc)) from None
                except Exception as exc:  # pyarrow raises several types for a corrupt file
                    raise ResourceError(f"remote {self.url}: shard index {table} cannot be read "
                                        f"({type(exc).__name__}: {str(exc).splitlines()[0][:160]})") from None
                for i, row in enumerate(data):
                    rows[_shard_row(row, f"remote {self.url}: shard index {table} row {i}")] = row
        self._shards[version_rel] = rows
        return rows

    def read_range(self, rel: str, offset: int, size: int, dest: Path, what: str) -> None:
        """Write bytes ``[offset, offset + size)`` of the file ``rel`` to ``dest`` with one Range request."""
        from huggingface_hub import get_session, hf_hub_url
        from huggingface_hub.utils import build_hf_headers

        if size == 0:
            atomic_write(dest, b"")
            return
        url = hf_hub_url(self.repo_id, self._full(rel), repo_type=self.repo_type, revision=self.revision,
                         endpoint=self.endpoint)
        headers = build_hf_headers(headers={"Range": f"bytes={offset}-{offset + size - 1}"})
        _stream_to(lambda: get_session().stream("GET", url, headers=headers, follow_redirects=True, timeout=60),
                   self.url, rel, dest, what, expect=(offset, size))

    def upload_dir(self, local_dir: Path, rel_prefix: str, message: str = "") -> None:
        api = self._api()
        target = self._full(rel_prefix)
        api.create_repo(self.repo_id, repo_type=self.repo_type, exist_ok=True)
        if any(f.startswith(target + "/") for f in self._repo_files()):
            raise ResourceError(f"remote {self.url}: {rel_prefix} already exists (versions are immutable)")
        api.upload_folder(repo_id=self.repo_id, folder_path=str(local_dir), path_in_repo=target,
                          repo_type=self.repo_type, revision=self.revision,
                          commit_message=message or f"Add {rel_prefix}")

    def put_bytes(self, rel: str, data: bytes, message: str = "") -> None:
        api = self._api()
        api.create_repo(self.repo_id, repo_type=self.repo_type, exist_ok=True)
        api.upload_file(path_or_fileobj=data, path_in_repo=self._full(rel), repo_id=self.repo_id,
                        repo_type=self.repo_type, revision=self.revision, commit_message=message or f"Update {rel}")

    def _repo_files(self) -> list[str]:
        from huggingface_hub.errors import RepositoryNotFoundError, RevisionNotFoundError

        try:
            return self._api().list_repo_files(self.repo_id, repo_type=self.repo_type, revision=self.revision)
        except (RepositoryNotFoundError, RevisionNotFoundError):
            return []

    def list_files(self, prefix: str = "") -> list[str]:
        full = self._full(prefix)
        cut = len(self.prefix) + 1 if self.prefix else 0
        return sorted(f[cut:] for f in self._repo_files() if not full or f.startswith(full.rstrip("/") + "/"))


class HttpRemote(Remote):
    """A plain HTTP(S) bucket read by URL, ``<base_url>/<path>`` (MolmoSpaces' R2 and GC buckets): read-only."""

    def __init__(self, base_url: str, timeout: float = 60.0) -> None:
        self.url, self.timeout = base_url.rstrip("/"), timeout
        self._client: httpx.Client | None = None
        self._pid = -1

    def client(self) -> httpx.Client:
        """One connection-pooling client per process (a client must not cross a fork)."""
        import httpx

        if self._client is None or self._pid != os.getpid():
            self._client, self._pid = httpx.Client(timeout=self.timeout, follow_redirects=True), os.getpid()
        return self._client

    def download(self, rel: str, dest: Path) -> None:
        url = f"{self.url}/{quote(rel)}"
        _stream_to(lambda: self.client().stream("GET", url), self.url, rel, Path(dest))

    def _read_only(self, *args, **kwargs) -> None:
        raise ResourceError(f"remote {self.url}: an HTTP bucket is read-only here; pack into a directory and "
                            "copy it into the bucket with the bucket's own tools")

    upload_dir = put_bytes = _read_only

    def list_files(self, prefix: str = "") -> list[str]:
        raise ResourceError(f"remote {self.url}: an HTTP bucket cannot be listed; name the version to install")


def _stream_to(open_stream, remote: str, rel: str, dest: Path, what: str = "the file",
               expect: tuple[int, int] | None = None) -> None:
    """Stream one HTTP response body into ``dest`` (atomically); every failure is one line.

    ``expect=(offset, size)`` for a Range request: the answer must be that exact range.
    """
    import httpx

    part = Path(f"{dest}.{uuid.uuid4().hex}.part")
    try:
        with open_stream() as resp:
            if resp.status_code >= 400:
                raise _status_error(remote, rel, resp.status_code)
            length = resp.headers.get("Content-Length")
            want = int(length) if length is not None and length.isdigit() else None
            if expect is not None:
                offset, size = expect
                got = resp.headers.get("Content-Range", "")
                if resp.status_code != 206 or not got.startswith(f"bytes {offset}-{offset + size - 1}/"):
                    raise ResourceError(f"remote {remote}: {rel}: the server did not answer the Range request for "
                                        f"{what} (HTTP {resp.status_code}, Content-Range {got or 'none'!r})")
                want = size
            n = 0
            with open(fileio.open_fd(part, os.O_WRONLY | os.O_CREAT | os.O_EXCL), "wb") as fh:
                for block in resp.iter_raw():
                    n += len(block)
                    if want is not None and n > want:
                        raise ResourceError(f"remote {remote}: {rel}: more bytes than the {want} announced for {what}")
                    fh.write(block)
        if want is not None and n != want:
            raise ResourceError(f"remote {remote}: {rel}: truncated response for {what} ({n} of {want} bytes)")
        fileio.replace(part, dest, root=Path(dest).parent)
    except httpx.HTTPError as exc:
        reason = str(exc).splitlines()[0][:160] if str(exc) else ""
        raise ResourceError(f"remote {remote}: {rel}: transfer of {what} failed "
                            f"({type(exc).__name__}: {reason})") from None
    finally:
        fileio.remove(part)


def _status_error(remote: str, rel: str, status: int) -> ResourceError:
    if status == 404:
        return RemoteNotFoundError(f"remote {remote}: {rel} not found (HTTP 404)")
    if status in (401, 403):
        return ResourceError(_denied(remote, rel, status))
    return ResourceError(f"remote {remote}: {rel}: HTTP {status}")


def _denied(remote: str, rel: str, status: int) -> str:
    hint = ("set HF_TOKEN to a token that can read this repo (the token is read from the environment "
            "and never logged)") if remote.startswith("hf://") else "the bucket is not public"
    return f"remote {remote}: access to {rel} denied (HTTP {status}); {hint}"


def _status(exc: Exception) -> int | None:
    response = getattr(exc, "response", None)
    return getattr(response, "status_code", None)


def _http_failure(remote: str, rel: str, status: int | None, exc: Exception) -> str:
    if status is not None:
        return str(_status_error(remote, rel, status))
    return f"remote {remote}: {rel}: {type(exc).__name__}: {str(exc).splitlines()[0][:160] if str(exc) else ''}"


def _shard_row(row: dict, where: str) -> str:
    def int_field(key: str, optional: bool = False) -> None:
        value = row.get(key)
        if value is None and optional:
            return
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            raise ResourceError(f"{where}: field {key} must be a non-negative integer, not {value!r}")

    if not isinstance(row.get("path"), str) or not row["path"]:
        raise ResourceError(f"{where}: field path must be an archive name")
    for key in ("shard_id", "offset", "size"):
        int_field(key)
    int_field("inflated_size", optional=True)
    return row["path"]


def open_remote(url: str | os.PathLike, endpoint: str | None = None) -> Remote:
    """``/path``, ``file:///path``, ``http(s)://bucket``, ``hf://datasets/<ns>/<repo>[/<prefix>]`` or ``hf://models/…``."""
    text = str(url)
    if text.startswith("hf://"):
        parts = text[len("hf://"):].strip("/").split("/")
        kinds = {"datasets": "dataset", "models": "model"}
        if len(parts) < 3 or parts[0] not in kinds:
            raise ResourceError(f"remote {text!r}: expected hf://datasets/<namespace>/<repo>[/<prefix>]")
        return HfRemote("/".join(parts[1:3]), "/".join(parts[3:]), kinds[parts[0]], endpoint=endpoint)
    if text.startswith("file://"):
        return LocalRemote(unquote(urlparse(text).path))
    if text.startswith(("http://", "https://")):
        return HttpRemote(text)
    if "://" in text:
        raise ResourceError(f"remote {text!r}: unsupported scheme (use a directory, file://, http(s):// or hf://)")
    return LocalRemote(text)
