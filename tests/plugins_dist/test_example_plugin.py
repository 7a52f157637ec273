"""A third-party policy distribution pip-installed from its own directory is discovered.

Installs plugins/molmo-example-policy into a temporary ``--target`` directory (no deps, no
build isolation: offline) and runs the real console commands with ``PYTHONPATH`` pointing
there: ``molmo-plugins`` lists it, Hydra finds its ``policy/example_sine.yaml``, its benchmark pack
is ``benchmark=example_pick`` everywhere a shipped benchmark is, and ``molmo-serve`` serves it over
the openpi protocol and survives malformed frames.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from websockets.sync.client import connect

from molmo_lerobot.protocol.client import PolicyClient
from molmo_lerobot.protocol.codec import unpackb

pytest.importorskip("hatchling", reason="building the example plugin offline needs hatchling in the venv")

REPO = Path(__file__).resolve().parents[2]
PLUGIN_DIR = REPO / "plugins" / "molmo-example-policy"


@pytest.fixture(scope="module")
def target(tmp_path_factory) -> Path:
    target = tmp_path_factory.mktemp("site")
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
         "--no-index", "--target", str(target), str(PLUGIN_DIR)],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert (target / "molmo_example_policy" / "conf" / "policy" / "example_sine.yaml").is_file()
    return target


def env_with(target: Path) -> dict[str, str]:
    path = os.pathsep.join([str(target), *filter(None, [os.environ.get("PYTHONPATH")])])  # the code under test
    env = dict(os.environ, PYTHONPATH=path, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    return env


def script(name: str) -> list[str]:
    exe = Path(sys.executable).parent / name
    if exe.exists():
        return [str(exe)]
    module = {"molmo-plugins": "plugins", "molmo-serve": "serve"}[name]
    return [sys.executable, "-c", f"import sys; from molmo_lerobot.cli.{module} import main; sys.exit(main())"]


def test_molmo_plugins_lists_it(target):
    proc = subprocess.run(script("molmo-plugins"), env=env_with(target), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    line = next((ln for ln in proc.stdout.splitlines() if ln.split()[:1] == ["example_sine"]), None)
    assert line is not None, proc.stdout
    assert "molmo-example-policy" in line and "0.1.0" in line and "ok" in line and "policy" in line
    # Not installed in the venv itself: discovery came from the target directory.
    bare = subprocess.run(script("molmo-plugins"), capture_output=True, text=True, timeout=120,
                          env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    assert "example_sine" not in bare.stdout


def test_code_and_hydra_config_are_discovered(target):
    code = (
        "from molmo_lerobot.config import compose; from molmo_lerobot.policies.factory import make_policy\n"
        "from molmo_lerobot.plugins import Plugins; from omegaconf import OmegaConf\n"
        "cfg = compose(['policy=example_sine', 'policy.amplitude=0.3'])\n"
        "p = make_policy(Plugins(), OmegaConf.to_container(cfg.policy))\n"
        "print(type(p).__module__, type(p).__name__, cfg.policy.amplitude, cfg.policy.period_s)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], env=env_with(target), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["molmo_example_policy", "SinePolicy", "0.3", "2.0"]


def test_its_benchmark_pack_is_found_by_name(target):
    """``example_pick`` ships in the distribution: the run config, the registry, the Gymnasium ids and
    ``molmo-bench validate`` know it by name, as they know the shipped benchmarks."""
    code = (
        "from molmo_lerobot.config import compose; from molmo_lerobot.plugins import Plugins\n"
        "from molmo_lerobot.benchmark.registry import find_benchmark\n"
        "from molmo_lerobot.gym_env import register_benchmarks\n"
        "cfg = compose(['benchmark=example_pick'])\n"
        "path = find_benchmark(cfg.benchmark.name, Plugins())\n"
        "ids = register_benchmarks()\n"
        "print(cfg.benchmark.name, path.parent.parent.name, path.name,\n"
        "      'molmo_lerobot/example_pick' in ids, 'molmo_lerobot/pick_v1' in ids)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], env=env_with(target), capture_output=True, text=True,
                          timeout=180)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["example_pick", "molmo_example_policy", "example_pick", "True", "True"]
    check = subprocess.run([sys.executable, "-c", "import sys; from molmo_lerobot.cli.bench import main; "
                            "sys.exit(main(['validate', '--schema-only', 'example_pick']))"],
                           env=env_with(target), capture_output=True, text=True, timeout=120)
    assert check.returncode == 0, check.stderr
    assert "episodes   2 over 1 houses" in check.stdout


def test_molmo_serve_serves_it_and_survives_malformed_frames(target):
    proc = subprocess.Popen([*script("molmo-serve"), "policy=example_sine", "port=0"], env=env_with(target),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        match = re.search(r"ws://127\.0\.0\.1:(\d+)", line)
        assert match, line + proc.stderr.read() if proc.poll() is not None else line
        port = int(match.group(1))
        good = PolicyClient("127.0.0.1", port, timeout_s=10)
        assert good.connect()["policy"] == "example_sine"
        obs = {"qpos": {"arm": np.zeros(7), "gripper": np.zeros(1)}, "step": 5, "prompt": "wave"}
        first = good.infer(obs)
        assert first["arm"].shape == (7,) and np.isfinite(first["arm"]).all()
        with connect(f"ws://127.0.0.1:{port}", compression=None) as bad:
            assert unpackb(bad.recv(timeout=10))["server"] == "molmo-serve"
            bad.send(b"\xc1\xc1 garbage")
            assert "malformed msgpack" in bad.recv(timeout=10)
        np.testing.assert_array_equal(good.infer(obs)["arm"], first["arm"])
        good.close()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_molmo_serve_unknown_policy_is_one_clear_line(target):
    proc = subprocess.run([*script("molmo-serve"), "policy=exampel_sine"], env=env_with(target),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "did you mean 'example_sine'" in proc.stderr
