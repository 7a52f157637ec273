"""Stand-ins for MolmoSpaces' remotes on 127.0.0.1, filled from small trees made in the tests.

- :class:`BucketStandin`: a plain HTTP bucket (their R2/GC layout), serving a directory.
- :func:`publish_bucket`: write a tree as one version in their bucket layout (``.tar.zst``
  archives, an archive→size-in-MB manifest and an archive→path-trie index).
- :func:`publish_hf`: mirror a bucket version into a Hub stand-in repo in their Hub layout
  (the archives packed into ``shards/NNNNN.tar`` plus a ``pkgs`` parquet table of archive,
  shard, offset and size in ``<prefix>__<data_type>__<source>__<version>/``).
"""

from __future__ import annotations

import gzip
import io
import json
import os
import tarfile
import threading
from collections import Counter
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urlsplit

import zstandard

REMOTE_MANIFEST = "mjthor_resource_file_to_size_mb.json"
TRIES = "mjthor_resources_combined_meta.json.gz"


class _QuietServer(ThreadingHTTPServer):
    """Drops handler errors (a client that hung up on purpose) instead of printing them into
    whichever test's captured stderr is current."""

    def handle_error(self, request, client_address) -> None:
        pass


class BucketStandin:
    """Serves ``root`` over HTTP. ``gets``/``sent`` count GETs and body bytes per path; ``faults``
    maps a path to ``"truncate"``, ``"401"``, ``"403"`` or ``"500"``."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.gets: Counter[str] = Counter()
        self.sent: Counter[str] = Counter()
        self.faults: dict[str, str] = {}
        self.lock = threading.Lock()
        handler = type("Handler", (_BucketHandler,), {"bucket": self})
        self.server = _QuietServer(("127.0.0.1", 0), handler)
        self.server.daemon_threads = True
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self._thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def __enter__(self) -> BucketStandin:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.server.shutdown()
        self.server.server_close()
        self._thread.join(timeout=5)

    def archive_gets(self) -> Counter[str]:
        return Counter({p: n for p, n in self.gets.items() if p.endswith(".tar.zst")})


class _BucketHandler(BaseHTTPRequestHandler):
    bucket: BucketStandin
    protocol_version = "HTTP/1.1"

    def log_message(self, *args) -> None:
        pass

    def do_GET(self) -> None:
        rel = unquote(urlsplit(self.path).path).lstrip("/")
        path = (self.bucket.root / rel).resolve()
        with self.bucket.lock:
            self.bucket.gets[rel] += 1
            fault = self.bucket.faults.get(rel)
        if fault in ("401", "403", "500"):
            return self._send(int(fault), b"denied" if fault != "500" else b"boom")
        if not path.is_relative_to(self.bucket.root.resolve()) or not path.is_file():
            return self._send(404, b"<Error><Code>NoSuchKey</Code></Error>")
        data = path.read_bytes()
        with self.bucket.lock:
            self.bucket.sent[rel] += len(data) if fault != "truncate" else len(data) // 2
        if fault == "truncate":
            self.send_response(200)
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data[: len(data) // 2])
            self.wfile.flush()
            self.close_connection = True
            return
        self._send(200, data)

    def _send(self, status: int, body: bytes) -> None:
        self.send_response(status)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Content-Type", "application/octet-stream")
        self.end_headers()
        self.wfile.write(body)


def _trie(paths: list[str]) -> dict:
    """A path trie whose single-child chains are joined with ``/`` (their compacted form)."""
    root: dict = {}
    for p in paths:
        node = root
        for part in p.split("/"):
            node = node.setdefault(part, {})

    def compact(node: dict) -> dict:
        out = {}
        for key, child in node.items():
            child = compact(child)
            while len(child) == 1 and next(iter(child.values())):
                (k, v), = child.items()
                key, child = f"{key}/{k}", v
            out[key] = child
        return out

    return compact(root)


def publish_bucket(tree: Path, bucket: Path, data_type: str, source: str, version: str,
                   group=lambda rel: rel.split("/")[0]) -> dict[str, list[str]]:
    """Write ``tree`` as ``data_type/source/version`` in their bucket layout; one archive per group.

    Archives hold directory members too (as ``tar`` of a directory does). Returns
    ``{archive: [paths]}``.
    """
    tree = Path(tree)
    vdir = Path(bucket) / data_type / source / version
    vdir.mkdir(parents=True)
    groups: dict[str, list[str]] = {}
    for dirpath, dirnames, filenames in os.walk(tree):
        dirnames.sort()
        for name in sorted(filenames) + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
            rel = Path(dirpath, name).relative_to(tree).as_posix()
            groups.setdefault(f"{source}_{group(rel).replace('.', '_')}.tar.zst", []).append(rel)
    sizes, tries = {}, {}
    for archive, paths in sorted(groups.items()):
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w", format=tarfile.PAX_FORMAT) as tar:
            dirs = sorted({str(Path(p).parent) for p in paths} - {"."})
            for d in dirs:
                for parent in reversed([d, *[str(x) for x in Path(d).parents if str(x) != "."]]):
                    if parent not in tar.getnames():
                        tar.add(tree / parent, arcname=parent, recursive=False)
            for p in paths:
                tar.add(tree / p, arcname=p, recursive=False)
        blob = zstandard.ZstdCompressor(level=3).compress(buf.getvalue())
        (vdir / archive).write_bytes(blob)
        sizes[archive] = round(len(blob) / 1e6, 6)
        tries[archive] = _trie(paths)
    (vdir / REMOTE_MANIFEST).write_text(json.dumps(sizes))
    (vdir / TRIES).write_bytes(gzip.compress(json.dumps(tries).encode()))
    return groups


def publish_hf(hub, bucket: Path, repo_id: str, prefix: str, data_type: str, source: str, version: str,
               n_shards: int = 2) -> dict[str, dict]:
    """Mirror one bucket version into the Hub stand-in in their Hub layout; returns the parquet rows by archive."""
    import tempfile

    import pyarrow as pa
    import pyarrow.parquet as pq
    from huggingface_hub import HfApi

    rel = f"{data_type}/{source}/{version}"
    src = Path(bucket) / rel
    archives = sorted(json.loads((src / REMOTE_MANIFEST).read_text()))
    rows: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / prefix / rel
        (out / "shards").mkdir(parents=True)
        for name in (REMOTE_MANIFEST, TRIES):
            (out / name).write_bytes((src / name).read_bytes())
        for shard in range(n_shards):
            with tarfile.open(out / "shards" / f"{shard:05d}.tar", "w", format=tarfile.PAX_FORMAT) as tar:
                for name in archives[shard::n_shards]:
                    tar.add(src / name, arcname=name)
            with tarfile.open(out / "shards" / f"{shard:05d}.tar") as tar:
                for m in tar.getmembers():
                    rows[m.name] = {"path": m.name, "shard_id": shard, "offset": m.offset_data, "size": m.size}
        table = Path(tmp) / f"{prefix}/{rel}".replace("/", "__")
        table.mkdir()
        pq.write_table(pa.Table.from_pylist(sorted(rows.values(), key=lambda r: r["path"])),
                       table / "pkgs-00000-of-00001.parquet")
        api = HfApi()
        api.create_repo(repo_id, repo_type="dataset", exist_ok=True)
        api.upload_folder(repo_id=repo_id, folder_path=tmp, repo_type="dataset")
    return rows
