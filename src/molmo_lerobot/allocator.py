"""glibc's allocator in a worker process: two arenas, and freed memory handed back after each episode.

glibc gives each thread that allocates an arena of its own, up to eight per core, and keeps what is
freed in them for reuse. A recording worker runs some 40 threads (each camera's SVT-AV1 encoder
starts ~17 per episode, Mesa's llvmpipe one per core), so a pick_v3 worker held 16 arenas on a
2-core box whose free lists grew by ~60 MB with every house loaded: 2.0 of its 4.6 GB resident after
14 houses was freed memory (``mallinfo2``'s ``fordblks``), against 1.3 GB in use and flat; bounded, it
stays at 2.9 GB (``tests/perf/test_worker_memory.py``, the README's "Memory per worker"). A worker
therefore starts with :data:`ARENA_MAX` arenas (:func:`bound_arenas`) and returns the free pages of
every arena after each episode (:func:`release_free_memory`); a process started by exec (the LIBERO env
server) gets the same bound from its environment (:func:`child_env`), read when it starts.

Elsewhere than glibc (musl, macOS) every function here does nothing.
"""

from __future__ import annotations

import ctypes

#: arenas a worker's threads share (glibc's ``M_ARENA_MAX``)
ARENA_MAX = 2
_M_ARENA_MAX = -8  # mallopt's parameter number, from glibc's malloc.h


def _glibc() -> ctypes.CDLL | None:
    try:
        libc = ctypes.CDLL(None)
    except OSError:
        return None
    return libc if hasattr(libc, "mallopt") and hasattr(libc, "malloc_trim") else None


def bound_arenas(n: int = ARENA_MAX) -> None:
    """Let this process's threads share at most ``n`` arenas from now on (those made before stay).
    Call it before the process starts threads: glibc fixes the bound at the first arena it makes past
    eight (``arena_test``)."""
    libc = _glibc()
    if libc is not None:
        libc.mallopt(_M_ARENA_MAX, n)


def release_free_memory() -> None:
    """Hand the free pages of every arena back to the system (``malloc_trim(0)``): tens of milliseconds."""
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)


def child_env() -> dict[str, str]:
    """The environment that gives a process started by exec the same arena bound."""
    return {"MALLOC_ARENA_MAX": str(ARENA_MAX)}
