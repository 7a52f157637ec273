"""The environment a worker process starts with, set on import before MuJoCo is imported (it
picks its OpenGL backend then): the first module a worker's fork server imports."""

from __future__ import annotations

from molmo_lerobot.gl import use_headless_gl

use_headless_gl()
