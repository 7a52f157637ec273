"""The environment a worker process starts with, set on import before MuJoCo is imported (it
picks its OpenGL backend then): the first module a worker's fork server imports."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")
