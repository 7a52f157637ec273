"""The environment a worker process starts with, set on import before MuJoCo is imported (it
picks its OpenGL backend then) and before any thread starts (the allocator's arena bound): the
first module a worker's fork server imports.

SIGINT is ignored from here on, as a worker ignores it: a Ctrl-C at the terminal reaches the whole process
group, and the supervisor, not the signal, decides when the fork server and its workers stop (a server
interrupted while it imports would print a traceback and fail the next worker's start)."""

from __future__ import annotations

import signal

from molmo_lerobot.allocator import bound_arenas
from molmo_lerobot.gl import use_headless_gl

use_headless_gl()
bound_arenas()
signal.signal(signal.SIGINT, signal.SIG_IGN)
