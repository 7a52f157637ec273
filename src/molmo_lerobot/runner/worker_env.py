"""The environment a worker process starts with, set on import before MuJoCo is imported (it
picks its OpenGL backend then) and before any thread starts (the allocator's arena bound): the
first module a worker's fork server imports."""

from __future__ import annotations

from molmo_lerobot.allocator import bound_arenas
from molmo_lerobot.gl import use_headless_gl

use_headless_gl()
bound_arenas()
