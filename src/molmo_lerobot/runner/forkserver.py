"""The run's fork server: workers forked from a process that already imported what they import.

A spawned worker re-imports MuJoCo, the harness and its policy's libraries (torch, LeRobot: 7 s
for ``lerobot.policies.factory`` on a 2-core box, ~0.9 GB each) before it can run anything.
:class:`PreloadedForkServer` starts one server process per run that imports them once; every
worker is then forked from it, starts in milliseconds and shares those pages copy-on-write.

It is a multiprocessing fork server of its own, not the module-wide one ``set_forkserver_preload``
configures, so other code in the process (Gymnasium's vector envs, a user's pool) keeps its own.

No CUDA context or EGL display can reach a worker through it: the server is a fresh interpreter
started by exec (never a fork of the supervisor, whatever the supervisor holds) and it only imports
modules; importing torch creates no CUDA context and importing MuJoCo no EGL display (each is
created by a worker's first use). Every worker checks this when it starts
(:func:`inherited_gpu_state`) and refuses to run otherwise.

The server forks from its main thread; importing LeRobot leaves it idle library thread pools
(OpenCV's, jemalloc's, OpenBLAS's), which re-initialise in a forked child: a forked worker runs
OpenCV's and torch's parallel kernels (``tests/runner/test_worker_start.py``, slow). A policy whose
libraries cannot be forked that way runs with ``executor.start_method=spawn``.
"""

from __future__ import annotations

import io
import os
import sys
from collections.abc import Iterable
from multiprocessing import forkserver, popen_forkserver, process, reduction, spawn, util
from multiprocessing.context import ForkServerProcess, set_spawning_popen
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from molmo_lerobot.context import RunContext

#: What every worker imports, whatever its policy; the first sets the worker environment.
BASE_PRELOAD = ("molmo_lerobot.runner.worker_env", "numpy", "mujoco", "molmo_lerobot.runner.local",
                "molmo_lerobot.context", "molmo_lerobot.runner.episode_env")


def preload_modules(plugin_modules: Iterable[str] = (), extra: Iterable[str] = ()) -> list[str]:
    """The server's preload list: :data:`BASE_PRELOAD`, the plugin modules, then ``extra`` (the
    policy's and recorders' libraries), each once, in that order."""
    return list(dict.fromkeys([*BASE_PRELOAD, *plugin_modules, *extra]))


class PreloadedForkServer:
    """A fork server that imports ``modules`` first; :meth:`process` makes processes forked from it."""

    def __init__(self, modules: Iterable[str]) -> None:
        self.modules = list(modules)
        self._server = forkserver.ForkServer()
        self._server.set_forkserver_preload(self.modules)

    def start(self) -> None:
        """Start the server (it imports in the background; the first fork waits for it)."""
        self._server.ensure_running()

    @property
    def pid(self) -> int | None:
        return self._server._forkserver_pid

    def process(self, target: Any, args: tuple[Any, ...], name: str) -> ForkServerProcess:
        """A daemon process running ``target(*args)``, forked from this server once started."""
        proc = ForkServerProcess(target=target, args=args, name=name, daemon=True)
        proc._Popen = _Launcher(self._server)  # type: ignore[attr-defined,method-assign]
        return proc

    def stop(self) -> None:
        """End the server (its children live on; each ends with its supervisor)."""
        if self._server._forkserver_pid is not None:
            self._server._stop()


class _Launcher:
    """``Process._Popen`` for one server; pickled with the process as a harmless stand-in."""

    def __init__(self, server: forkserver.ForkServer | None) -> None:
        self.server = server

    def __call__(self, process_obj: process.BaseProcess) -> _Popen:
        return _Popen(process_obj, self.server)

    def __reduce__(self) -> tuple[Any, ...]:
        return _Launcher, (None,)


class _Popen(popen_forkserver.Popen):
    """The standard forkserver ``Popen``, asking ``server`` instead of the module-wide server."""

    def __init__(self, process_obj: process.BaseProcess, server: forkserver.ForkServer) -> None:
        self._server = server
        super().__init__(process_obj)

    def _launch(self, process_obj: process.BaseProcess) -> None:
        prep_data = spawn.get_preparation_data(process_obj._name)
        buf = io.BytesIO()
        set_spawning_popen(self)
        try:
            reduction.dump(prep_data, buf)
            reduction.dump(process_obj, buf)
        finally:
            set_spawning_popen(None)
        self.sentinel, w = self._server.connect_to_new_process(self._fds)
        parent_w = os.dup(w)  # the child's "parent alive" sentinel, as the standard Popen keeps
        self.finalizer = util.Finalize(self, util.close_fds, (parent_w, self.sentinel))
        with open(w, "wb", closefd=True) as f:
            f.write(buf.getbuffer())
        self.pid = forkserver.read_signed(self.sentinel)


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


def worker_preload(ctx: RunContext, policy: dict[str, Any], recorders: Iterable[Any]) -> list[str]:
    """What a worker of this run imports: the base, every plugin module, the policy's factory
    module and its declared ``preload``, and the recorders' modules (LeRobot's dataset writer)."""
    from types import ModuleType

    plugins = [p.__name__ for p in ctx.plugins.pm.get_plugins() if isinstance(p, ModuleType)]
    policy_type = ctx.plugins.policy(str(policy["name"]))
    extra = [policy_type.factory.__module__, *policy_type.preload, *(type(r).__module__ for r in recorders)]
    return preload_modules(sorted(plugins), extra)
