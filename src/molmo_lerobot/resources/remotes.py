"""Where packed resources live: a local directory (``file://``) or a Hugging Face repo (``hf://``).

Layout on every remote, below its root: ``<data_type>/<source>/<version>/`` holding
``manifest.json``, ``index.json.gz`` and ``archives/<name>.tar.zst``.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import uuid
from abc import ABC, abstractmethod
from pathlib import Path
from urllib.parse import unquote, urlparse

from molmo_lerobot.fileio import atomic_open, atomic_write
from molmo_lerobot.resources.errors import ResourceError


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
            raise ResourceError(f"remote {self.url}: {rel} not found")
        with open(src, "rb") as fsrc, atomic_open(dest, "wb") as fdst:
            shutil.copyfileobj(fsrc, fdst)

    def upload_dir(self, local_dir: Path, rel_prefix: str, message: str = "") -> None:
        target = self._path(rel_prefix)
        if target.exists():
            raise ResourceError(f"remote {self.url}: {rel_prefix} already exists (versions are immutable)")
        target.parent.mkdir(parents=True, exist_ok=True)
        staging = target.parent / f".{target.name}.{uuid.uuid4().hex}.tmp"
        shutil.copytree(local_dir, staging)
        os.replace(staging, target)  # appears complete or not at all

    def put_bytes(self, rel: str, data: bytes, message: str = "") -> None:
        path = self._path(rel)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, data)

    def list_files(self, prefix: str = "") -> list[str]:
        base = self._path(prefix) if prefix else self.root
        if not base.is_dir():
            return []
        out = []
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
        kind = {"dataset": "datasets/", "model": "models/"}[repo_type]
        self.url = f"hf://{kind}{repo_id}" + (f"/{self.prefix}" if self.prefix else "")

    def _api(self):
        from huggingface_hub import HfApi

        return HfApi(endpoint=self.endpoint)

    def _full(self, rel: str) -> str:
        return f"{self.prefix}/{rel}".strip("/") if self.prefix else rel

    def download(self, rel: str, dest: Path) -> None:
        from huggingface_hub import hf_hub_download
        from huggingface_hub.errors import EntryNotFoundError, RepositoryNotFoundError, RevisionNotFoundError

        dest = Path(dest)
        with tempfile.TemporaryDirectory(prefix=".hf-", dir=dest.parent) as tmp:
            try:
                got = hf_hub_download(self.repo_id, self._full(rel), repo_type=self.repo_type, revision=self.revision,
                                      local_dir=tmp, endpoint=self.endpoint)
            except (EntryNotFoundError, RepositoryNotFoundError, RevisionNotFoundError) as exc:
                raise ResourceError(f"remote {self.url}: {rel} not found ({type(exc).__name__})") from None
            os.replace(got, dest)

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


def open_remote(url: str | os.PathLike, endpoint: str | None = None) -> Remote:
    """``/path``, ``file:///path``, ``hf://datasets/<ns>/<repo>[/<prefix>]`` or ``hf://models/…``."""
    text = str(url)
    if text.startswith("hf://"):
        parts = text[len("hf://"):].strip("/").split("/")
        kinds = {"datasets": "dataset", "models": "model"}
        if len(parts) < 3 or parts[0] not in kinds:
            raise ResourceError(f"remote {text!r}: expected hf://datasets/<namespace>/<repo>[/<prefix>]")
        return HfRemote("/".join(parts[1:3]), "/".join(parts[3:]), kinds[parts[0]], endpoint=endpoint)
    if text.startswith("file://"):
        return LocalRemote(unquote(urlparse(text).path))
    if "://" in text:
        raise ResourceError(f"remote {text!r}: unsupported scheme (use a directory, file:// or hf://)")
    return LocalRemote(text)
