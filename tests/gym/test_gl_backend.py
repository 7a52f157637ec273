"""The Gymnasium env and ``--env.type=molmo`` choose MuJoCo's GL backend themselves (as molmo-eval),
say in one line what to set when MuJoCo cannot render, and exit quietly when left open."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

GYM = """
import gymnasium as gym
import molmo_lerobot.gym_env
env = gym.make("molmo_lerobot/pick_v1", horizon=3)
obs, _ = env.reset(seed=0)
env.step(env.action_space.sample())
print("rendered", obs["pixels"]["exterior"].shape)
"""  # the env is left open: the interpreter's exit closes it

PLUGIN = """
from lerobot_env_molmo import MolmoEnvConfig
cfg = MolmoEnvConfig(task="pick_v1")
print("features", sorted(cfg.features))
"""


def _run(code: str, **env: str | None) -> subprocess.CompletedProcess:
    environ = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}
    environ.update({k: v for k, v in env.items() if v is not None})
    return subprocess.run([sys.executable, "-c", code], env=environ, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("code, out, chosen", [(GYM, "rendered (224, 224, 3)", None),
                                               (GYM, "rendered (224, 224, 3)", ""),  # set but empty: unset to MuJoCo
                                               pytest.param(PLUGIN, "pixels/exterior", None, marks=pytest.mark.slow)])
def test_renders_with_mujoco_gl_unset_and_exits_quietly(code, out, chosen):
    proc = _run(code, MUJOCO_GL=chosen)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert out in proc.stdout
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr[-2000:]


def test_a_backend_that_cannot_render_is_one_line_saying_what_to_set():
    proc = _run(GYM, MUJOCO_GL="glfw")  # no DISPLAY: GLFW has no context to give
    assert proc.returncode != 0
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("molmo_lerobot.gl.GLError: MuJoCo cannot render with MUJOCO_GL=glfw")
    assert "set MUJOCO_GL=egl" in last
    assert "Exception ignored" not in proc.stderr  # no second traceback from the half-built renderer


@pytest.mark.slow
def test_lerobot_reports_a_gl_failure_as_such_not_as_a_config_parse_error():
    proc = _run(PLUGIN, MUJOCO_GL="glfw")
    assert proc.returncode == 1
    lines = [line for line in proc.stderr.splitlines() if "GLFWError" not in line and "warnings.warn" not in line]
    assert lines == [lines[-1]] and lines[-1].startswith("error: --env.type=molmo: MuJoCo cannot render"), proc.stderr
    assert "parsing" not in proc.stderr


def test_a_gl_failure_is_the_machines_not_the_episodes():
    """Run with a backend that cannot render, every episode was an *episode* error that resume never reruns."""
    from molmo_lerobot.errors import INFRASTRUCTURE, error_kind
    from molmo_lerobot.gl import gl_error

    assert error_kind(gl_error(RuntimeError("an OpenGL platform library has not been loaded"))) == INFRASTRUCTURE
