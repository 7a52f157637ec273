"""The suite protocol: one msgpack message per frame (4-byte big-endian length, then the
:mod:`~molmo_lerobot.protocol.codec` bytes) over two pipes between the harness and a child process.

A suite's env lives in its own virtualenv (LIBERO needs robosuite 1.4, this project 1.5), so the harness
talks to it as to a child process: :class:`SuiteProcess` starts ``python -m <server module>`` with that
venv's interpreter, waits for its hello (sent once the server's imports are done) and sends requests
``{"op": ..., ...}``; the server (:func:`serve`) answers each with one reply, ``{"error": "..."}`` when the
request failed (:class:`SuiteError`, the episode's error). A pipe, not a socket: one harness worker owns one
env process.

The child is the parent's alone: the frames travel on two pipes of their own, its stdin is ``/dev/null``
(nothing in it can wait on a prompt) and its stdout goes nowhere (the suite's own chatter: LIBERO's
``[info] using task orders``), its stderr is the parent's. It runs in a process group of its own (a Ctrl-C
at the terminal is the parent's to handle) and is killed when the thread that started it ends
(``PR_SET_PDEATHSIG``), whatever ends it. A child that cannot start, dies, breaks the protocol or leaves a
request unanswered for :func:`timeout_s` is killed, and the failure is the machinery's, not the episode's
(:class:`SuiteProcessError`, an infrastructure error): a worker starts a new one at its next episode and
the supervisor retries the episode.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import select
import signal
import struct
import subprocess
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

from molmo_lerobot.errors import InfrastructureError, MolmoError
from molmo_lerobot.protocol.codec import packb, unpackb

_LENGTH = struct.Struct(">I")
#: the child's end of the protocol: ``"<request fd>,<reply fd>"``
PIPE_ENV = "MOLMO_SUITE_PIPE"
#: the pid of the child's parent when it was started (it exits at once when that has already gone)
PARENT_ENV = "MOLMO_SUITE_PARENT"
#: seconds a suite process may take to start (its hello) and to answer any one request
TIMEOUT_ENV, DEFAULT_TIMEOUT_S = "MOLMO_SUITE_TIMEOUT_S", 180.0
#: seconds a closing suite process may take to exit before it is killed
CLOSE_TIMEOUT_S = 10.0
_PR_SET_PDEATHSIG = 1


class SuiteError(MolmoError, RuntimeError):
    """The suite's env process refused a request (its one-line reason)."""


class SuiteProcessError(SuiteError, InfrastructureError):
    """The suite's env process could not start, died, broke the protocol or did not answer in time; it is
    killed. The machinery's failure, not the episode's (``resume=true`` reruns the episode)."""


def timeout_s() -> float:
    """Seconds a suite process has to start and to answer each request: ``$MOLMO_SUITE_TIMEOUT_S``, else
    :data:`DEFAULT_TIMEOUT_S`."""
    raw = os.environ.get(TIMEOUT_ENV)
    if raw is None:
        return DEFAULT_TIMEOUT_S
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise SuiteError(f"{TIMEOUT_ENV}: expected a number of seconds > 0, got {raw!r}")
    return value


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


def serve(handlers: Mapping[str, Callable[..., Any]] | Callable[[], Mapping[str, Callable[..., Any]]]) -> None:
    """Answer the parent's requests until it says ``close`` or its pipe closes. ``handlers``, or a function
    that makes them (the suite's own imports and set-up): its failure is the hello's ``error``, the one line
    the parent reports."""
    _die_with_parent()
    spec = os.environ.pop(PIPE_ENV, None)
    if spec is None:
        raise SystemExit(f"suite server: no {PIPE_ENV} (it is started by molmo_lerobot.suites.pipe.SuiteProcess)")
    request_fd, reply_fd = (int(fd) for fd in spec.split(","))
    inp, out = os.fdopen(request_fd, "rb"), os.fdopen(reply_fd, "wb")
    try:
        ops = handlers() if callable(handlers) else handlers
    except (Exception, SystemExit) as exc:  # said in the hello: the parent's one line
        write_frame(out, {"error": f"{type(exc).__name__}: {exc}"})
        return
    write_frame(out, {"ready": True})
    while (request := read_frame(inp)) is not None:
        op = request.pop("op", None)
        if op == "close":
            write_frame(out, {"ok": True})
            break
        try:
            if op not in ops:
                raise SuiteError(f"unknown op {op!r} (known: {', '.join(sorted(ops))})")
            reply = ops[op](**request)
        except Exception as exc:  # the harness records it against the episode; the server keeps serving
            reply = {"error": f"{type(exc).__name__}: {exc}"}
        write_frame(out, reply)


def serve_env_server(make: Callable[[], Any]) -> None:
    """:func:`serve` the env server ``make`` builds (its imports and set-up are the hello's): its ``tasks``,
    ``reset``, ``step`` and ``close_envs`` are the ops, and its envs are closed however the serving ends."""
    made: list[Any] = []

    def start() -> dict[str, Callable[..., Any]]:
        server = make()
        made.append(server)
        return {"tasks": server.tasks, "reset": server.reset, "step": server.step, "close_envs": server.close_envs}

    try:
        serve(start)
    finally:
        for server in made:
            server.close_envs()


def _die_with_parent() -> None:
    """Have the kernel SIGKILL this process when the thread that started it ends (Linux); exit now if the
    parent is already gone (it died before this process asked)."""
    parent = int(os.environ.pop(PARENT_ENV, "0"))
    with contextlib.suppress(OSError, AttributeError):  # not Linux: the parent's close() ends it
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if parent and os.getppid() != parent:
        os._exit(1)


class SuiteProcess:
    """A suite's env server running as a child process of this one (``python -m module`` with ``python``).
    ``remedy``: what to do when it cannot start (ends that error's line)."""

    def __init__(self, python: Path, module: str, env: Mapping[str, str] | None = None,
                 pythonpath: Sequence[Path] = (), remedy: str = "") -> None:
        self.name = f"suite env {module}"
        self.remedy = f"; {remedy}" if remedy else ""
        if not Path(python).exists():
            raise SuiteProcessError(f"{self.name}: no interpreter at {python}{self.remedy}")
        self.timeout_s = timeout_s()
        child_env = {**os.environ, **(env or {})}
        path = [str(p) for p in pythonpath] + [p for p in child_env.get("PYTHONPATH", "").split(os.pathsep) if p]
        child_env["PYTHONPATH"] = os.pathsep.join(path)
        request_r, request_w = os.pipe()
        reply_r, reply_w = os.pipe()
        child_env[PIPE_ENV], child_env[PARENT_ENV] = f"{request_r},{reply_w}", str(os.getpid())
        try:
            self._proc = subprocess.Popen([str(python), "-m", module], stdin=subprocess.DEVNULL,
                                          stdout=subprocess.DEVNULL, env=child_env, pass_fds=(request_r, reply_w),
                                          process_group=0)
        except BaseException:
            for fd in (request_w, reply_r):
                os.close(fd)
            raise
        finally:
            for fd in (request_r, reply_w):
                os.close(fd)
        self._requests, self._replies = os.fdopen(request_w, "wb"), reply_r
        try:
            hello = self._receive("start")
            if "error" in hello:
                self.kill()
                raise SuiteProcessError(f"{self.name}: could not start: {hello['error']}{self.remedy}")
        except BaseException:
            self.close()  # killed by now: its pipes
            raise

    @property
    def pid(self) -> int:
        return self._proc.pid

    @property
    def alive(self) -> bool:
        """Whether it can take a request (not exited, not killed after a failure)."""
        return self._proc.poll() is None

    def request(self, op: str, **fields: Any) -> Any:
        """Send one request; its reply. A refusal is a :class:`SuiteError`; anything that leaves the
        process unusable kills it and is a :class:`SuiteProcessError`."""
        if not self.alive:
            raise SuiteProcessError(f"{self.name}: the process has ended ({self._exit()}); see its stderr")
        try:
            write_frame(self._requests, {"op": op, **fields})
        except OSError as exc:
            raise self._lost(f"cannot send {op!r} ({exc})") from None
        reply = self._receive(op)
        if isinstance(reply, dict) and "error" in reply:
            raise SuiteError(f"{self.name}: {op}: {reply['error']}")
        return reply

    def _receive(self, op: str, timeout_s: float | None = None) -> Any:
        """The next reply, within ``timeout_s`` (:attr:`timeout_s`); anything else (the end of the pipe, a
        broken frame, no answer in time, an interruption: the pipe is out of step) kills the process."""
        deadline = time.monotonic() + (self.timeout_s if timeout_s is None else timeout_s)
        try:
            head = self._read(_LENGTH.size, deadline, op)
            reply = unpackb(self._read(_LENGTH.unpack(head)[0], deadline, op))
        except SuiteProcessError:
            raise
        except Exception as exc:  # a frame that is not the protocol's
            raise self._lost(f"broke the protocol answering {op!r} ({type(exc).__name__}: {exc})") from None
        except BaseException:  # KeyboardInterrupt, a worker asked to stop: the request is abandoned
            self.kill()
            raise
        if not isinstance(reply, dict):
            raise self._lost(f"broke the protocol answering {op!r} (a {type(reply).__name__}, not a map)")
        return reply

    def _read(self, size: int, deadline: float, op: str) -> bytes:
        buf = bytearray()
        ready = select.poll()  # not select(): a worker may hold more than FD_SETSIZE files
        ready.register(self._replies, select.POLLIN)
        while len(buf) < size:
            left = deadline - time.monotonic()
            if left <= 0 or not ready.poll(left * 1000):
                what = "to start" if op == "start" else f"to answer {op!r}"
                raise self._lost(f"took more than {self.timeout_s:g} s {what} ({TIMEOUT_ENV} sets the limit)"
                                 + self.remedy * (op == "start"))
            chunk = os.read(self._replies, min(size - len(buf), 1 << 20))
            if not chunk:
                self._proc.wait(timeout=CLOSE_TIMEOUT_S)  # its end of the pipe closed as it exited
                what = "while starting" if op == "start" else f"during {op!r}"
                raise self._lost(f"exited ({self._exit()}) {what}; its stderr says why" + self.remedy * (op == "start"))
            buf += chunk
        return bytes(buf)

    def _lost(self, what: str) -> SuiteProcessError:
        """Kill the process; the error saying ``what`` became of it."""
        self.kill()
        return SuiteProcessError(f"{self.name} (process {self._proc.pid}) {what}")

    def _exit(self) -> str:
        code = self._proc.returncode
        if code is not None and code < 0:
            with contextlib.suppress(ValueError):
                return f"signal {signal.Signals(-code).name}"
        return f"exit code {code}"

    def kill(self) -> None:
        """End the process now, however it is (stopped, hung, gone)."""
        if self._proc.poll() is None:
            self._proc.kill()
        self._proc.wait()

    def close(self) -> None:
        """Ask the process to exit; kill it when it does not answer or exit within :data:`CLOSE_TIMEOUT_S`."""
        if self.alive:
            with contextlib.suppress(SuiteError, OSError):
                write_frame(self._requests, {"op": "close"})
                self._receive("close", CLOSE_TIMEOUT_S)
            try:
                self._proc.wait(timeout=CLOSE_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.kill()
        if self._replies >= 0:
            with contextlib.suppress(OSError):
                self._requests.close()
            os.close(self._replies)
            self._replies = -1

    def __enter__(self) -> SuiteProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
