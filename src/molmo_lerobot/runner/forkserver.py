"""The run's fork server: workers forked from a process that already imported what they import.

A spawned worker re-imports MuJoCo, the harness and its policy's libraries (torch, LeRobot: 7 s
for ``lerobot.policies.factory`` on a 2-core box, ~0.9 GB each) before it can run anything.
:class:`PreloadedForkServer` starts one server process per run that imports them once; every
worker is then forked from it, starts in milliseconds and shares those pages copy-on-write. A
:class:`ForkServerPool` keeps servers from one run to the next in one process (a sweep's jobs).

It is a multiprocessing fork server of its own, not the module-wide one ``set_forkserver_preload``
configures, so other code in the process (Gymnasium's vector envs, a user's pool) keeps its own.

No CUDA context or EGL display can reach a worker through it: the server is a fresh interpreter
started by exec (never a fork of the supervisor, whatever the supervisor holds) and it only imports
modules; importing torch creates no CUDA context and importing MuJoCo no EGL display (each is
created by a worker's first use). Every worker checks this when it starts
(:func:`inherited_gpu_state`) and refuses to run otherwise.

A worker's liveness never depends on the server: the supervisor holds a pidfd on each worker
(readable once it has ended, whoever its parent is), and only its exit status comes from the
server, which reaps it. A server that is killed or stopped (SIGSTOP) therefore neither hides a
worker's death nor fakes one; the status of a worker that ended while its server was lost is
unreported (:func:`exit_status_lost`). A lost server fails the next start at once
(:class:`ForkServerLost`, never a wait on a stopped server), and the transport replaces it
(:meth:`PreloadedForkServer.restart`).

The server forks from its main thread; importing LeRobot leaves it idle library thread pools
(OpenCV's, jemalloc's, OpenBLAS's), which re-initialise in a forked child: a forked worker runs
OpenCV's and torch's parallel kernels (``tests/runner/test_worker_start.py``, slow). A policy whose
libraries cannot be forked that way runs with ``executor.start_method=spawn``.

It drives CPython's private multiprocessing API, which typeshed does not declare: hence the
``type: ignore[attr-defined]`` on those lines.
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import sys
import time
from collections.abc import Iterable
from multiprocessing import forkserver, popen_forkserver, process, reduction, spawn, util
from multiprocessing.connection import wait
from multiprocessing.context import ForkServerProcess, set_spawning_popen
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot.errors import MolmoError

if TYPE_CHECKING:
    from molmo_lerobot.context import RunContext

#: How local worker processes start: forked from the run's fork server, or each a fresh interpreter
START_METHODS = ("forkserver", "spawn")
#: What every worker imports, whatever its policy; the first sets the worker environment.
BASE_PRELOAD = ("molmo_lerobot.runner.worker_env", "numpy", "mujoco", "molmo_lerobot.runner.local",
                "molmo_lerobot.context", "molmo_lerobot.runner.episode_env")


#: Seconds an ended worker's exit status may take to come from its fork server (which reaps it).
STATUS_WAIT_S = 2.0
#: Seconds a stopping server may take to exit once its last worker has (then it is killed).
STOP_TIMEOUT_S = 10.0


class ForkServerLost(MolmoError, OSError):
    """The fork server died or was stopped before it forked the worker asked for."""


def preload_modules(plugin_modules: Iterable[str] = (), extra: Iterable[str] = ()) -> list[str]:
    """The server's preload list: :data:`BASE_PRELOAD`, the plugin modules, then ``extra`` (the
    policy's and recorders' libraries), each once, in that order."""
    return list(dict.fromkeys([*BASE_PRELOAD, *plugin_modules, *extra]))


class PreloadedForkServer:
    """A fork server that imports ``modules`` first; :meth:`process` makes processes forked from it."""

    def __init__(self, modules: Iterable[str]) -> None:
        self.modules = list(modules)
        self._server = self._new()
        self.forked = False  # whether this server (or one it replaced) has forked a process: then one
        # that cannot fork was lost (killed, stopped), not broken by its preload
        self.origin: tuple[Any, ...] | None = None  # what it was started with (server_origin), once started

    def _new(self) -> forkserver.ForkServer:
        server = forkserver.ForkServer()
        server.set_forkserver_preload(self.modules)
        return server

    def start(self) -> None:
        """Start the server (it imports in the background; the first fork waits for it)."""
        if self.pid is None:
            self.origin = server_origin(self.modules)
        self._server.ensure_running()

    @property
    def pid(self) -> int | None:
        return self._server._forkserver_pid  # type: ignore[attr-defined]

    def state(self) -> str | None:
        """Why the server cannot fork now (``gone``, ``stopped``, ...), or None while it runs."""
        if self.pid is None:
            return "not started"
        try:
            code = Path(f"/proc/{self.pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            return "gone"
        return {"T": "stopped", "t": "stopped", "Z": "dead", "X": "dead"}.get(code)

    def process(self, target: Any, args: tuple[Any, ...], name: str) -> ForkServerProcess:
        """A daemon process running ``target(*args)``, forked from this server once started. Its
        ``start()`` raises :class:`ForkServerLost` (or ``EOFError``) when the server is lost first."""
        proc = ForkServerProcess(target=target, args=args, name=name, daemon=True)
        proc._Popen = _Launcher(self)  # type: ignore[method-assign]
        return proc

    def restart(self) -> None:
        """End this server however it is (dead, stopped, not answering) and start a fresh one. The
        processes it forked live on: nothing but their exit status depended on it."""
        self.kill()
        self.start()

    def kill(self) -> None:
        """End this server at once, however it is; the processes it forked live on."""
        pid = self.pid
        if pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, 0)
            os.close(self._server._forkserver_alive_fd)  # type: ignore[attr-defined]
        self._server = self._new()

    def wait_pid(self, status_r: int) -> int:
        """The pid the server reports on ``status_r`` for the process just asked for; raises
        :class:`ForkServerLost` when the server dies or is stopped first (the wait for it to finish
        importing its preload is unbounded, as the standard fork server's)."""
        while not wait([status_r], timeout=0.5):
            if (why := self.state()) is not None:
                raise ForkServerLost(f"the worker fork server (process {self.pid}) is {why}")
        return forkserver.read_signed(status_r)

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> None:
        """End the server: it exits once every process it forked has (each holds its "alive" pipe);
        one still there ``timeout_s`` later (stopped, say) is killed. Its children live on."""
        pid = self.pid
        if pid is None:
            return
        os.close(self._server._forkserver_alive_fd)  # type: ignore[attr-defined]
        deadline = time.monotonic() + timeout_s
        try:
            while not os.waitpid(pid, os.WNOHANG)[0]:
                if time.monotonic() > deadline:
                    os.kill(pid, signal.SIGKILL)
                    os.waitpid(pid, 0)
                    break
                time.sleep(0.02)
        except ChildProcessError:
            pass  # reaped elsewhere
        self._server = self._new()


def server_origin(modules: Iterable[str]) -> tuple[Any, ...]:
    """What a fork server started now would give its workers besides their job: its preload, and
    this process's ``sys.path``, working directory and environment (which it imports them under)."""
    return tuple(modules), tuple(sys.path), os.getcwd(), tuple(sorted(os.environ.items()))


class ForkServerPool:
    """Fork servers kept from one run to the next in this process (the jobs of a ``molmo-eval -m``
    sweep, the runs of a test session), so that a run after the first skips the server's imports.

    A run borrows an idle server of the same :func:`server_origin` (one started now would be the
    same), else a new one, and gives it back once its workers have ended. A server is lent to one run
    at a time: one lost during a run (killed, stopped) is that run's to replace, as without a pool, and
    one found not running when given back or borrowed is killed, never lent. At most ``keep`` idle
    servers are kept (the one idle longest is stopped); :meth:`close`, or leaving ``with``, stops them.
    ``ignored_env`` names environment variables no worker reads that change between runs (pytest's
    ``PYTEST_CURRENT_TEST``): a worker of a lent server sees their value from the server's start."""

    def __init__(self, keep: int = 2, ignored_env: Iterable[str] = ()) -> None:
        self.keep = keep
        self.ignored_env = frozenset(ignored_env)
        self._idle: list[PreloadedForkServer] = []

    def _key(self, origin: tuple[Any, ...] | None) -> tuple[Any, ...] | None:
        if origin is None:
            return None
        modules, path, cwd, env = origin
        return modules, path, cwd, tuple(item for item in env if item[0] not in self.ignored_env)

    def borrow(self, modules: Iterable[str]) -> PreloadedForkServer:
        """A started server preloading ``modules``, as a fresh one started now would be."""
        modules = list(modules)
        key = self._key(server_origin(modules))
        for server in self._idle:
            if self._key(server.origin) == key:
                self._idle.remove(server)
                if server.state() is None:
                    return server
                server.kill()  # lost while idle
                break
        server = PreloadedForkServer(modules)
        server.start()
        return server

    def give_back(self, server: PreloadedForkServer) -> None:
        """Keep ``server`` for a later run if it is running, else end it."""
        if server.state() is not None:
            server.kill()
            return
        self._idle.append(server)
        while len(self._idle) > self.keep:
            self._idle.pop(0).stop()

    def close(self) -> None:
        """Stop every idle server."""
        while self._idle:
            self._idle.pop().stop()

    def __enter__(self) -> ForkServerPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def exit_status_lost(proc: process.BaseProcess) -> bool:
    """Whether ``proc`` (from :meth:`PreloadedForkServer.process`) ended without its fork server
    reporting how (the server was killed or stopped): its ``exitcode`` 255 then says nothing."""
    return bool(getattr(proc._popen, "status_lost", False))  # type: ignore[attr-defined]


class _Launcher:
    """``Process._Popen`` for one server; pickled with the process as a harmless stand-in."""

    def __init__(self, server: PreloadedForkServer | None) -> None:
        self.server = server

    def __call__(self, process_obj: process.BaseProcess) -> _Popen:
        assert self.server is not None
        return _Popen(process_obj, self.server)

    def __reduce__(self) -> tuple[Any, ...]:
        return _Launcher, (None,)


class _Popen(popen_forkserver.Popen):
    """The standard forkserver ``Popen``, asking ``server`` instead of the module-wide server, and
    watching the process through a pidfd (``sentinel``) rather than through the server."""

    def __init__(self, process_obj: process.BaseProcess, server: PreloadedForkServer) -> None:
        self._server = server
        self.status_lost = False
        super().__init__(process_obj)

    def _launch(self, process_obj: process.BaseProcess) -> None:
        prep_data = spawn.get_preparation_data(process_obj._name)  # type: ignore[attr-defined]
        buf = io.BytesIO()
        set_spawning_popen(self)
        try:
            reduction.dump(prep_data, buf)
            reduction.dump(process_obj, buf)
        finally:
            set_spawning_popen(None)
        self._status, w = self._server._server.connect_to_new_process(self._fds)  # type: ignore[attr-defined]
        parent_w = os.dup(w)  # the child's "parent alive" sentinel, as the standard Popen keeps
        try:
            self.pid = self._server.wait_pid(self._status)  # before the job is written: a stopped server
        except BaseException:                                # never forks a child to read it
            util.close_fds(w, parent_w, self._status)  # type: ignore[attr-defined]
            raise
        self._server.forked = True
        try:
            self.sentinel = os.pidfd_open(self.pid)
        except (ProcessLookupError, AttributeError):  # already gone (the server has its status), or no pidfds
            self.sentinel = self._status
        fds = (parent_w, self._status) + ((self.sentinel,) if self.sentinel != self._status else ())
        self.finalizer = util.Finalize(self, util.close_fds, fds)  # type: ignore[attr-defined]
        with contextlib.suppress(BrokenPipeError), open(w, "wb", closefd=True) as f:
            f.write(buf.getbuffer())  # a worker that died before reading its job: its sentinel says so

    def _send_signal(self, sig: int) -> None:
        """Through the pidfd: a worker outliving its server is reaped by init, and its pid may be reused."""
        if self.returncode is None and self.sentinel != self._status:
            with contextlib.suppress(ProcessLookupError):
                signal.pidfd_send_signal(self.sentinel, sig)
        else:
            super()._send_signal(sig)  # type: ignore[misc]

    def poll(self, flag: int = os.WNOHANG) -> int | None:
        if self.returncode is None:
            if not wait([self.sentinel], 0 if flag == os.WNOHANG else None):
                return None
            self.returncode = self._exit_status()
        return self.returncode

    def _exit_status(self) -> int:
        """The ended process's exit status, from the server that reaps it; 255 and ``status_lost``
        when the server is gone or does not report it within :data:`STATUS_WAIT_S`."""
        if wait([self._status], STATUS_WAIT_S):
            with contextlib.suppress(OSError, EOFError):
                return forkserver.read_signed(self._status)
        self.status_lost = True
        return 255


def inherited_gpu_state() -> str | None:
    """What GPU state this process holds before it used a GPU (a CUDA context, an EGL display),
    or ``None``; a worker calls it first thing, so anything found came from its parent."""
    torch = sys.modules.get("torch")
    if torch is not None and torch.cuda.is_initialized():
        return "a CUDA context"
    egl = sys.modules.get("mujoco.egl")
    if egl is not None and getattr(egl, "EGL_DISPLAY", None) is not None:
        return "an EGL display"
    return None


def worker_preload(run: RunContext, policy: dict[str, Any], recorders: Iterable[Any]) -> list[str]:
    """What a worker of this run imports: the base, every plugin module, the policy's factory
    module and its declared ``preload``, and the recorders' modules (LeRobot's dataset writer)."""
    from types import ModuleType

    plugins = [p.__name__ for p in run.plugins.pm.get_plugins() if isinstance(p, ModuleType)]
    policy_type = run.plugins.policy(str(policy["name"]))
    extra = [policy_type.factory.__module__, *policy_type.preload, *(type(r).__module__ for r in recorders)]
    return preload_modules(sorted(plugins), extra)
