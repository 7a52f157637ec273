"""MuJoCo's OpenGL backend: headless EGL unless the user chose one, and one line when none works.

MuJoCo reads ``MUJOCO_GL`` once, when ``mujoco`` is first imported; unset, it picks GLFW, which
needs a display. Every process of ours that may render calls :func:`use_headless_gl` before it
imports MuJoCo: ``molmo-eval``, its workers, the Gymnasium env and ``--env.type=molmo``.
"""

from __future__ import annotations

import os
import sys

from molmo_lerobot.errors import InfrastructureError

#: the backend chosen when ``MUJOCO_GL`` is unset: headless, on a GPU or Mesa's software EGL
HEADLESS_GL = "egl"


class GLError(InfrastructureError):
    """MuJoCo could not create an OpenGL context to render with: the machine's fault, not the episode's
    (recorded as infrastructure; ``resume=true`` reruns it once ``MUJOCO_GL`` is fixed)."""


def use_headless_gl() -> None:
    """Set ``MUJOCO_GL=egl`` unless the environment chose a backend (call it before importing MuJoCo); an empty
    ``MUJOCO_GL`` chooses none (MuJoCo reads it as unset and picks GLFW)."""
    if not os.environ.get("MUJOCO_GL", "").strip():
        os.environ["MUJOCO_GL"] = HEADLESS_GL


def gl_error(exc: BaseException) -> GLError:
    """One line for MuJoCo's failure to render: the backend it used and what to set instead."""
    chosen = os.environ.get("MUJOCO_GL")
    late = " (MuJoCo was imported before MUJOCO_GL was set)" if chosen and _imported_with() != chosen else ""
    reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return GLError(f"MuJoCo cannot render with MUJOCO_GL={_imported_with() or '(unset: GLFW, needs a display)'}"
                   f"{late}: {reason}; set MUJOCO_GL=egl (a GPU or Mesa's libEGL) or MUJOCO_GL=osmesa "
                   "(software, slow) in the environment before Python starts")


def _imported_with() -> str | None:
    """The ``MUJOCO_GL`` the imported MuJoCo chose its context with (None: not imported, or unset then)."""
    gl_context = sys.modules.get("mujoco.gl_context")
    chosen = getattr(gl_context, "_MUJOCO_GL", None)
    return chosen or None
