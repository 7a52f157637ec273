"""A local stand-in for the Hugging Face Hub HTTP API, so the real ``huggingface_hub`` client runs.

Pure standard library: an ``http.server`` in a daemon thread, repos kept as snapshot
commits (``{path: blob}``) with branches and tags, blobs stored content-addressed under a
directory. It answers what ``HfApi`` / ``hf_hub_download`` / ``snapshot_download`` and
LeRobot's ``push_to_hub`` / ``LeRobotDataset(repo_id)`` call:

- ``GET /api/{type}s`` (``author``, ``search``: ``HfApi.list_datasets`` & co, one page)
- ``POST /api/repos/create``, ``DELETE /api/repos/delete``, ``GET /api/agent-harnesses`` (empty),
  ``POST /api/validate-yaml`` (accepts every card)
- ``GET /api/{type}s/{repo}[/revision/{rev}]`` (repo info with ``sha`` and ``siblings``)
- ``GET /api/{type}s/{repo}/tree/{rev}[/{path}]`` (``recursive``), ``POST …/paths-info/{rev}``
- ``GET /api/{type}s/{repo}/refs``, ``GET …/commits/{rev}``
- ``POST|DELETE /api/{type}s/{repo}/branch/{name}``, ``POST …/tag/{rev}``, ``DELETE …/tag/{tag}``
- ``POST /api/{type}s/{repo}/preupload/{rev}`` (every file "regular": no LFS, no Xet)
- ``POST /api/{type}s/{repo}/commit/{rev}`` (ndjson: header, file, deletedFile, deletedFolder)
- ``HEAD|GET /[datasets/]{repo}/resolve/{rev}/{path}`` with ``ETag``, ``X-Repo-Commit`` and
  single-range ``Range`` requests (``206`` with ``Content-Range``, ``416`` outside the file)

Errors carry ``X-Error-Code`` (``RepoNotFound``, ``RevisionNotFound``, ``EntryNotFound``) so
the client raises its usual exceptions. Tokens are ignored unless ``token`` is set (then a
request without ``Authorization: Bearer <token>`` gets 401). For tests: ``sent`` counts the
body bytes served per file path and ``ranges`` records each Range read; ``faults`` maps a
path to ``"truncate"`` (announce the full length, send half, close).
"""

from __future__ import annotations

import base64
import hashlib
import json
import re
import threading
import time
from datetime import UTC, datetime
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs, unquote, urlsplit

REPO_TYPES = {"models": "model", "datasets": "dataset", "spaces": "space"}
_URL_PREFIX = {"model": "", "dataset": "datasets/", "space": "spaces/"}


class HubError(Exception):
    def __init__(self, status: int, message: str, code: str | None = None, **extra) -> None:
        super().__init__(message)
        self.status, self.message, self.code, self.extra = status, message, code, extra


def git_blob_sha1(data: bytes) -> str:
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


class Repo:
    """One repository: commits are full snapshots ``{path: [sha256, size, git_sha1]}``."""

    def __init__(self, repo_type: str, repo_id: str, private: bool) -> None:
        self.repo_type, self.repo_id, self.private = repo_type, repo_id, private
        self.commits: dict[str, dict] = {}
        self.branches: dict[str, str] = {}
        self.tags: dict[str, str] = {}
        root = self._commit(None, {}, "initial commit")
        self.branches["main"] = root

    def _commit(self, parent: str | None, files: dict, message: str) -> str:
        body = {"parent": parent, "files": files, "message": message, "date": time.time_ns()}
        oid = hashlib.sha1(json.dumps(body, sort_keys=True).encode()).hexdigest()
        self.commits[oid] = {**body, "id": oid}
        return oid

    def resolve(self, rev: str) -> str:
        if rev in self.branches:
            return self.branches[rev]
        if rev in self.tags:
            return self.tags[rev]
        if rev in self.commits:
            return rev
        raise HubError(404, f"Invalid rev id: {rev}", "RevisionNotFound")

    def files(self, rev: str) -> dict:
        return self.commits[self.resolve(rev)]["files"]

    def to_json(self) -> dict:
        return {"type": self.repo_type, "id": self.repo_id, "private": self.private,
                "branches": self.branches, "tags": self.tags, "commits": self.commits}


class _QuietServer(ThreadingHTTPServer):
    """Drops handler errors (a client that hung up on purpose) instead of printing them into
    whichever test's captured stderr is current."""

    def handle_error(self, request, client_address) -> None:
        pass


class HubStandin:
    """The stand-in's state plus its HTTP server. Use as a context manager or ``start()``/``stop()``."""

    def __init__(self, root: str | Path, host: str = "127.0.0.1", port: int = 0) -> None:
        self.root = Path(root)
        (self.root / "blobs").mkdir(parents=True, exist_ok=True)
        self.repos: dict[tuple[str, str], Repo] = {}
        self.lock = threading.RLock()
        self.requests: list[tuple[str, str]] = []  # (method, path) of every request, for assertions
        self.fail_commits: int | None = None  # an HTTP status: every commit fails with it (a Hub outage)
        self.sent: dict[str, int] = {}  # file path in repo -> body bytes served
        self.ranges: list[tuple[str, int, int]] = []  # (file path, start, end) of every Range read
        self.faults: dict[str, str] = {}  # file path in repo -> "truncate"
        self.token: str | None = None
        handler = type("Handler", (_Handler,), {"hub": self})
        self.server = _QuietServer((host, port), handler)
        self.server.daemon_threads = True
        self.endpoint = f"http://{host}:{self.server.server_address[1]}"
        self._thread: threading.Thread | None = None

    def start(self) -> HubStandin:
        self._thread = threading.Thread(target=self.server.serve_forever, name="hub-standin", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def __enter__(self) -> HubStandin:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- state ---------------------------------------------------------------------------
    def repo(self, repo_type: str, repo_id: str) -> Repo:
        try:
            return self.repos[(repo_type, repo_id)]
        except KeyError:
            raise HubError(404, f"Repository Not Found for url: {repo_type}s/{repo_id}", "RepoNotFound") from None

    def blob(self, sha256: str) -> Path:
        return self.root / "blobs" / sha256

    def put_blob(self, data: bytes) -> list:
        sha = hashlib.sha256(data).hexdigest()
        path = self.blob(sha)
        if not path.exists():
            tmp = path.with_suffix(f".{threading.get_ident()}.tmp")
            tmp.write_bytes(data)
            tmp.replace(path)
        return [sha, len(data), git_blob_sha1(data)]

    def save(self, repo: Repo) -> None:
        path = self.root / "repos" / repo.repo_type / f"{repo.repo_id}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(repo.to_json(), indent=1))

    def read_file(self, repo_type: str, repo_id: str, path: str, revision: str = "main") -> bytes:
        """Test helper: the bytes of ``path`` at ``revision``."""
        with self.lock:
            entry = self.repo(repo_type, repo_id).files(revision)[path]
        return self.blob(entry[0]).read_bytes()


def _entry(path: str, item: list) -> dict:
    return {"type": "file", "oid": item[2], "size": item[1], "path": path}


def _folder(path: str) -> dict:
    return {"type": "directory", "oid": hashlib.sha1(path.encode()).hexdigest(), "path": path}


def _tree(files: dict, base: str, recursive: bool) -> list[dict]:
    base = base.strip("/")
    prefix = base + "/" if base else ""
    out: dict[str, dict] = {}
    for path, item in sorted(files.items()):
        if not path.startswith(prefix):
            continue
        rest = path[len(prefix):].split("/")
        for depth in range(1, len(rest)):
            folder = prefix + "/".join(rest[:depth])
            if recursive or depth == 1:
                out.setdefault(folder, _folder(folder))
            if not recursive:
                break
        if recursive or len(rest) == 1:
            out[path] = _entry(path, item)
    if base and not out and base not in files:
        raise HubError(404, f"Entry not found: {base}", "EntryNotFound")
    return list(out.values())


class _Handler(BaseHTTPRequestHandler):
    hub: HubStandin
    protocol_version = "HTTP/1.1"

    def log_message(self, *args) -> None:  # keep test output clean
        pass

    # -- plumbing ------------------------------------------------------------------------
    def _body(self) -> bytes:
        if self.headers.get("Transfer-Encoding", "").lower() == "chunked":
            chunks = []
            while True:
                size = int(self.rfile.readline().strip().split(b";")[0], 16)
                if size == 0:
                    self.rfile.readline()
                    return b"".join(chunks)
                chunks.append(self.rfile.read(size))
                self.rfile.readline()
        n = int(self.headers.get("Content-Length") or 0)
        return self.rfile.read(n) if n else b""

    def _json_body(self) -> dict:
        raw = self._body()
        if not raw:
            return {}
        if self.headers.get("Content-Type", "").startswith("application/x-www-form-urlencoded"):
            return {k: v if len(v) > 1 or k == "paths" else v[0] for k, v in parse_qs(raw.decode()).items()}
        return json.loads(raw)

    def _send(self, status: int, payload=None, headers: dict | None = None, raw: bytes | None = None) -> None:
        body = raw if raw is not None else (b"" if payload is None else json.dumps(payload).encode())
        self.send_response(status)
        if raw is None:
            self.send_header("Content-Type", "application/json")
        for k, v in (headers or {}).items():
            self.send_header(k, str(v))
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _dispatch(self) -> None:
        url = urlsplit(self.path)
        self.hub.requests.append((self.command, url.path))
        query = {k: v[-1] for k, v in parse_qs(url.query).items()}
        segs = url.path.strip("/").split("/")
        try:
            if self.hub.token is not None and self.headers.get("Authorization") != f"Bearer {self.hub.token}":
                raise HubError(401, "Invalid credentials in Authorization header")
            with self.hub.lock:
                if segs[0] == "api":
                    self._api(segs[1:], query)
                else:
                    self._resolve(segs)
        except HubError as exc:
            headers = {"X-Error-Message": exc.message}
            if exc.code:
                headers["X-Error-Code"] = exc.code
            self._send(exc.status, {"error": exc.message, **exc.extra}, headers)

    do_GET = do_POST = do_PUT = do_DELETE = do_HEAD = _dispatch

    # -- API -----------------------------------------------------------------------------
    def _api(self, segs: list[str], query: dict) -> None:
        hub = self.hub
        if segs[:2] == ["repos", "create"] and self.command == "POST":
            body = self._json_body()
            repo_type = body.get("type") or "model"
            name = body.get("name")
            if not name:
                raise HubError(400, "missing repo name")
            repo_id = f"{body['organization']}/{name}" if body.get("organization") else f"user/{name}"
            url = f"{hub.endpoint}/{_URL_PREFIX[repo_type]}{repo_id}"
            if (repo_type, repo_id) in hub.repos:
                raise HubError(409, "You already created this repo", url=url)  # the Hub returns the url too
            hub.repos[(repo_type, repo_id)] = repo = Repo(repo_type, repo_id, body.get("visibility") == "private")
            hub.save(repo)
            return self._send(200, {"url": url, "name": repo_id, "id": repo_id})
        if segs == ["validate-yaml"] and self.command == "POST":  # repo card check (client hard-codes huggingface.co)
            self._body()
            return self._send(200, {"errors": [], "warnings": []})
        if segs == ["agent-harnesses"]:  # the client's agent-detection registry: nothing to detect here
            return self._send(200, {"standardEnvVars": [], "harnesses": {}})
        if segs[:2] == ["repos", "delete"] and self.command == "DELETE":
            body = self._json_body()
            repo_id = f"{body['organization']}/{body['name']}" if body.get("organization") else f"user/{body['name']}"
            hub.repo(body.get("type") or "model", repo_id)
            del hub.repos[(body.get("type") or "model", repo_id)]
            return self._send(200, {})
        if len(segs) == 1 and segs[0] in REPO_TYPES and self.command == "GET":  # list_datasets(author=, search=)
            author, search = query.get("author"), query.get("search")
            return self._send(200, [self._info(r, "main") for (kind, rid), r in sorted(hub.repos.items())
                                    if kind == REPO_TYPES[segs[0]] and (not author or rid.split("/")[0] == author)
                                    and (not search or search in rid.split("/", 1)[1])])
        if len(segs) < 3 or segs[0] not in REPO_TYPES:
            raise HubError(404, f"unknown API route /api/{'/'.join(segs)}")
        repo = hub.repo(REPO_TYPES[segs[0]], f"{unquote(segs[1])}/{unquote(segs[2])}")
        action, rest = (segs[3], [unquote(s) for s in segs[4:]]) if len(segs) > 3 else ("revision", ["main"])
        if action == "revision" and self.command == "GET":
            return self._send(200, self._info(repo, rest[0] if rest else "main"))
        if action == "tree" and self.command == "GET":
            recursive = query.get("recursive", "false").lower() in ("1", "true")
            return self._send(200, _tree(repo.files(rest[0]), "/".join(rest[1:]), recursive))
        if action == "paths-info" and self.command == "POST":
            files = repo.files(rest[0])
            paths = self._json_body().get("paths", [])
            out = [_entry(p, files[p]) for p in paths if p in files]
            out += [_folder(p) for p in paths if p not in files and any(f.startswith(p + "/") for f in files)]
            return self._send(200, out)
        if action == "refs" and self.command == "GET":
            def refs(kind: str, items: dict) -> list[dict]:
                return [{"name": n, "ref": f"refs/{kind}/{n}", "targetCommit": c} for n, c in sorted(items.items())]
            return self._send(200, {"branches": refs("heads", repo.branches), "tags": refs("tags", repo.tags),
                                    "converts": [], "pullRequests": []})
        if action == "commits" and self.command == "GET":
            out, oid = [], repo.resolve(rest[0] if rest else "main")
            while oid is not None:
                c = repo.commits[oid]
                out.append({"id": oid, "title": c["message"], "message": "", "authors": [{"user": "standin"}],
                            "date": _iso(c["date"])})
                oid = c["parent"]
            return self._send(200, out)
        if action == "branch":
            name = rest[0]
            if self.command == "POST":
                if name in repo.branches:
                    raise HubError(409, f"Reference already exists: refs/heads/{name}")
                start = self._json_body().get("startingPoint") or "main"
                repo.branches[name] = repo.resolve(start)
            elif self.command == "DELETE":
                if name not in repo.branches:
                    raise HubError(404, f"Invalid rev id: {name}", "RevisionNotFound")
                del repo.branches[name]
            hub.save(repo)
            return self._send(200, {})
        if action == "tag":
            if self.command == "POST":
                body = self._json_body()
                tag = body.get("tag")
                if tag in repo.tags:
                    raise HubError(409, f"Tag already exists: {tag}")
                repo.tags[tag] = repo.resolve(rest[0])
            elif self.command == "DELETE":
                if rest[0] not in repo.tags:
                    raise HubError(404, f"Invalid rev id: {rest[0]}", "RevisionNotFound")
                del repo.tags[rest[0]]
            hub.save(repo)
            return self._send(200, {})
        if action == "preupload" and self.command == "POST":
            files = repo.files(rest[0]) if rest[0] in repo.branches else {}
            wanted = self._json_body().get("files", [])
            return self._send(200, {"files": [
                {"path": f["path"], "uploadMode": "regular", "shouldIgnore": False,
                 "oid": files[f["path"]][2] if f["path"] in files else None} for f in wanted]})
        if action == "commit" and self.command == "POST":
            return self._commit(repo, rest[0])
        raise HubError(404, f"unknown API route /api/{'/'.join(segs)}")

    def _info(self, repo: Repo, rev: str) -> dict:
        sha = repo.resolve(rev)
        files = repo.commits[sha]["files"]
        return {"id": repo.repo_id, "_id": repo.repo_id, "author": repo.repo_id.split("/")[0], "sha": sha,
                "private": repo.private, "disabled": False, "gated": False, "downloads": 0, "likes": 0,
                "tags": [], "lastModified": _iso(repo.commits[sha]["date"]), "createdAt": _iso(0),
                "siblings": [{"rfilename": p, "size": item[1]} for p, item in sorted(files.items())]}

    def _commit(self, repo: Repo, branch: str) -> None:
        if self.hub.fail_commits:
            raise HubError(self.hub.fail_commits, "stand-in: the Hub refuses commits")
        if branch not in repo.branches:
            raise HubError(404, f"Invalid rev id: {branch}", "RevisionNotFound")
        lines = [json.loads(line) for line in self._body().splitlines() if line.strip()]
        header = next((x["value"] for x in lines if x.get("key") == "header"), {})
        parent = repo.branches[branch]
        if header.get("parentCommit") and header["parentCommit"] != parent:
            raise HubError(412, f"parent commit {header['parentCommit']} is not the head of {branch}")
        files = dict(repo.commits[parent]["files"])
        for item in lines:
            key, value = item.get("key"), item.get("value", {})
            if key == "file":
                if value.get("encoding", "base64") != "base64":
                    raise HubError(400, f"unsupported encoding {value.get('encoding')!r}")
                files[value["path"]] = self.hub.put_blob(base64.b64decode(value["content"]))
            elif key == "deletedFile":
                if value["path"] not in files:
                    raise HubError(404, f"A file with this name doesn't exist: {value['path']}", "EntryNotFound")
                del files[value["path"]]
            elif key == "deletedFolder":
                prefix = value["path"].rstrip("/") + "/"
                for p in [p for p in files if p.startswith(prefix)]:
                    del files[p]
            elif key == "lfsFile":
                raise HubError(400, "the stand-in stores every file as a regular file; LFS uploads are refused")
            elif key != "header":
                raise HubError(400, f"unknown commit operation {key!r}")
        oid = repo._commit(parent, files, header.get("summary", ""))
        repo.branches[branch] = oid
        self.hub.save(repo)
        url = f"{self.hub.endpoint}/{_URL_PREFIX[repo.repo_type]}{repo.repo_id}/commit/{oid}"
        self._send(200, {"commitUrl": url, "commitOid": oid, "pullRequestUrl": None, "success": True})

    # -- file downloads ------------------------------------------------------------------
    def _resolve(self, segs: list[str]) -> None:
        repo_type = "model"
        if segs and segs[0] in ("datasets", "spaces"):
            repo_type, segs = REPO_TYPES[segs[0]], segs[1:]
        if len(segs) < 5 or segs[2] != "resolve" or self.command not in ("GET", "HEAD"):
            raise HubError(404, f"unknown route {self.path}")
        repo = self.hub.repo(repo_type, f"{unquote(segs[0])}/{unquote(segs[1])}")
        rev, path = unquote(segs[3]), unquote("/".join(segs[4:]))
        sha = repo.resolve(rev)
        files = repo.commits[sha]["files"]
        if path not in files:
            raise HubError(404, f"Entry not found: {path}", "EntryNotFound")
        blob_sha, size, git_sha = files[path]
        headers = {"ETag": f'"{git_sha}"', "X-Repo-Commit": sha, "Accept-Ranges": "bytes",
                   "Content-Type": "application/octet-stream"}
        data = self.hub.blob(blob_sha).read_bytes()
        status = 200
        m = re.fullmatch(r"bytes=(\d*)-(\d*)", self.headers.get("Range", "").strip())
        if m and (m.group(1) or m.group(2)):
            if m.group(1):
                start = int(m.group(1))
                end = min(int(m.group(2)), size - 1) if m.group(2) else size - 1
            else:
                start, end = max(0, size - int(m.group(2))), size - 1
            if start >= size or start > end:
                return self._send(416, raw=b"", headers={"Content-Range": f"bytes */{size}"})
            data, status = data[start : end + 1], 206
            headers["Content-Range"] = f"bytes {start}-{end}/{size}"
            self.hub.ranges.append((path, start, end))
        if self.command == "GET":
            self.hub.sent[path] = self.hub.sent.get(path, 0) + len(data)
            if self.hub.faults.get(path) == "truncate":
                return self._truncate(status, data, headers)
        self._send(status, raw=data, headers=headers)

    def _truncate(self, status: int, data: bytes, headers: dict) -> None:
        """Announce the whole body, send half of it, and drop the connection."""
        self.send_response(status)
        for k, v in headers.items():
            self.send_header(k, str(v))
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data[: len(data) // 2])
        self.wfile.flush()
        self.close_connection = True


def pinned_client_factory(endpoint: str):
    """An ``huggingface_hub`` client factory whose every request goes to ``endpoint``.

    Some client calls hard-code ``https://huggingface.co`` (repo card validation); this keeps
    them, and anything else, off the network.
    """
    import httpx
    from huggingface_hub.utils._http import hf_request_event_hook

    target = httpx.URL(endpoint)

    class _Pinned(httpx.HTTPTransport):
        def handle_request(self, request: httpx.Request) -> httpx.Response:
            if (request.url.host, request.url.port) != (target.host, target.port):
                request.url = request.url.copy_with(scheme=target.scheme, host=target.host, port=target.port)
                request.headers["Host"] = f"{target.host}:{target.port}"
            return super().handle_request(request)

    def factory() -> httpx.Client:
        return httpx.Client(transport=_Pinned(), event_hooks={"request": [hf_request_event_hook]},
                            follow_redirects=True, timeout=None)

    return factory


def _iso(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, tz=UTC).strftime("%Y-%m-%dT%H:%M:%S.000Z")
