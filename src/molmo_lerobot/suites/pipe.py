"""The suite protocol: one msgpack message per frame (4-byte big-endian length, then the
:mod:`~molmo_lerobot.protocol.codec` bytes) over a child process's stdin and stdout.

A suite's env lives in its own virtualenv (LIBERO needs robosuite 1.4, this project 1.5), so the harness
talks to it as to a child process: :class:`SuiteProcess` starts ``python -m <server module>`` with that
venv's interpreter and sends requests ``{"op": ..., ...}``; the server (:func:`serve`) answers each with
one reply, ``{"error": "..."}`` when the request failed. A pipe, not a socket: one harness worker owns
one env process, and it dies with its parent (its stdin closes).
"""

from __future__ import annotations

import contextlib
import os
import struct
import subprocess
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

from molmo_lerobot.errors import InfrastructureError, MolmoError
from molmo_lerobot.protocol.codec import packb, unpackb

_LENGTH = struct.Struct(">I")


class SuiteError(MolmoError, RuntimeError):
    """The suite's env process refused a request (its one-line reason) or died."""


def write_frame(stream: IO[bytes], message: Any) -> None:
    data = packb(message)
    stream.write(_LENGTH.pack(len(data)) + data)
    stream.flush()


def read_frame(stream: IO[bytes]) -> Any:
    """The next message, or ``None`` at a clean end of stream."""
    head = stream.read(_LENGTH.size)
    if not head:
        return None
    if len(head) < _LENGTH.size:
        raise SuiteError("suite pipe: truncated frame header")
    (size,) = _LENGTH.unpack(head)
    data = stream.read(size)
    if len(data) < size:
        raise SuiteError(f"suite pipe: truncated frame ({len(data)} of {size} bytes)")
    return unpackb(data)


def serve(handlers: Mapping[str, Callable[..., Any]]) -> None:
    """Answer requests on stdin until it closes. The protocol's stdout is a private copy: anything the
    suite's own code prints goes to stderr instead of corrupting the frames."""
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    inp = os.fdopen(os.dup(0), "rb")
    while (request := read_frame(inp)) is not None:
        op = request.pop("op", None)
        if op == "close":
            write_frame(out, {"ok": True})
            break
        try:
            if op not in handlers:
                raise SuiteError(f"unknown op {op!r} (known: {', '.join(sorted(handlers))})")
            reply = handlers[op](**request)
        except Exception as exc:  # the harness records it against the episode; the server keeps serving
            reply = {"error": f"{type(exc).__name__}: {exc}"}
        write_frame(out, reply)


class SuiteProcess:
    """A suite's env server running as a child process of this one (``python -m module`` in ``venv``)."""

    def __init__(self, python: Path, module: str, env: Mapping[str, str] | None = None,
                 pythonpath: Sequence[Path] = ()) -> None:
        if not Path(python).exists():
            raise InfrastructureError(f"suite env: no interpreter at {python} (make .libero-venv builds it)")
        child_env = {**os.environ, **(env or {})}
        path = [str(p) for p in pythonpath] + [p for p in child_env.get("PYTHONPATH", "").split(os.pathsep) if p]
        child_env["PYTHONPATH"] = os.pathsep.join(path)
        self.module = module
        self._proc = subprocess.Popen([str(python), "-m", module], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      env=child_env)

    def request(self, op: str, **fields: Any) -> Any:
        stdin, stdout = self._proc.stdin, self._proc.stdout
        assert stdin is not None and stdout is not None  # both are pipes (Popen above)
        try:
            write_frame(stdin, {"op": op, **fields})
            reply = read_frame(stdout)
        except (BrokenPipeError, OSError) as exc:
            raise SuiteError(f"suite env {self.module}: the process died ({exc}); see its stderr") from exc
        if reply is None:
            raise SuiteError(f"suite env {self.module}: the process exited (code {self._proc.poll()}); "
                             "see its stderr")
        if isinstance(reply, dict) and "error" in reply:
            raise SuiteError(f"suite env {self.module}: {op}: {reply['error']}")
        return reply

    def close(self) -> None:
        if self._proc.poll() is None:
            with contextlib.suppress(SuiteError):
                self.request("close")
            try:
                self._proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()

    def __enter__(self) -> SuiteProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
