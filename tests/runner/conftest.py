"""Fixtures for runner tests: a misbehaving test policy installed as a real plugin distribution.

``faulty_policy`` writes ``molmo_test_policies`` (module + ``*.dist-info`` with an entry point in
the ``molmo_lerobot`` group + a Hydra ``policy/faulty.yaml``) into a temp dir, puts it on
``sys.path`` and ``PYTHONPATH`` (spawned workers inherit ``sys.path``; Ray workers the
environment) and clears the plugin cache. ``policy=faulty`` then holds the arm still and
misbehaves in the episodes named by ``policy.faults={episode_index: kind}``:

* ``sigkill`` — the worker SIGKILLs itself at the first ``act`` of that episode, every attempt;
* ``sigkill_once`` — the same, on the first attempt only (a marker file in ``policy.marker_dir``);
* ``hang`` — ``act`` never returns;
* ``raise`` — ``act`` raises ``RuntimeError``;
* ``nan`` / ``wrong_shape`` — ``act`` returns a non-finite / wrongly shaped arm action.

``policy.act_sleep_s`` slows every ``act``; every attempt appends the worker's pid to
``<marker_dir>/pids-<episode_index>`` at reset (so a test can ``kill -9`` it from outside);
``policy.fail_init=true`` makes the policy constructor raise.
"""

from __future__ import annotations

import json
import os
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pytest

from molmo_lerobot.plugins import get_plugins

MODULE = textwrap.dedent('''
    """Test-only policies that misbehave on purpose (see tests/runner/conftest.py)."""

    import os
    import signal
    import time
    from pathlib import Path

    import numpy as np

    from molmo_lerobot import hookimpl
    from molmo_lerobot.policies.base import Policy, PolicyType


    class FaultyPolicy(Policy):
        needs_images = False

        def __init__(self, cfg):
            if cfg.get("fail_init"):
                raise RuntimeError("faulty policy: refusing to start (fail_init=true)")
            self.faults = {int(k): str(v) for k, v in (cfg.get("faults") or {}).items()}
            self.marker_dir = Path(cfg.get("marker_dir") or ".")
            self.act_sleep_s = float(cfg.get("act_sleep_s") or 0.0)
            self.episode = -1

        def reset(self, ctx):
            self.episode = ctx.episode_index
            with open(self.marker_dir / f"pids-{self.episode}", "a") as f:
                f.write(f"{os.getpid()}\\n")

        def act(self, obs):
            kind = self.faults.get(self.episode)
            marker = self.marker_dir / f"crashed-{self.episode}"
            if kind == "sigkill" or (kind == "sigkill_once" and not marker.exists()):
                marker.touch()
                os.kill(os.getpid(), signal.SIGKILL)
            if kind == "hang":
                while True:
                    time.sleep(60)
            if kind == "raise":
                raise RuntimeError(f"faulty policy: raising in episode {self.episode}")
            if self.act_sleep_s:
                time.sleep(self.act_sleep_s)
            action = {g: (np.zeros(len(q)) if g == "gripper" else np.array(q, dtype=float))
                      for g, q in obs["qpos"].items()}
            if kind == "nan":
                action["arm"][0] = np.nan
            if kind == "wrong_shape":
                action["arm"] = np.zeros(len(action["arm"]) + 1)
            return action


    def make_faulty(cfg):
        return FaultyPolicy(cfg)


    @hookimpl
    def molmo_policies():
        return [PolicyType("faulty", make_faulty, "holds still; crashes, hangs or errs on request (tests)")]


    @hookimpl
    def molmo_config_dirs():
        return [str(Path(__file__).parent / "conf")]
''')

POLICY_YAML = textwrap.dedent("""\
    # Test-only policy (tests/runner/conftest.py): holds still, misbehaves in the episodes of `faults`.
    name: faulty
    faults: {}
    marker_dir: null
    act_sleep_s: 0.0
    fail_init: false
""")


def write_test_distribution(root: Path) -> Path:
    """Write the ``molmo_test_policies`` distribution into ``root`` (a future ``sys.path`` entry)."""
    pkg = root / "molmo_test_policies"
    (pkg / "conf" / "policy").mkdir(parents=True)
    (pkg / "__init__.py").write_text(MODULE)
    (pkg / "conf" / "policy" / "faulty.yaml").write_text(POLICY_YAML)
    info = root / "molmo_test_policies-0.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: molmo-test-policies\nVersion: 0.0\n")
    (info / "entry_points.txt").write_text("[molmo_lerobot]\nmolmo_test_policies = molmo_test_policies\n")
    return root


@pytest.fixture
def faulty_policy(tmp_path, monkeypatch):
    """Install ``policy=faulty`` for this test; yields its ``marker_dir`` and ``sys.path`` entry."""
    root = write_test_distribution(tmp_path / "site")
    markers = tmp_path / "markers"
    markers.mkdir()
    monkeypatch.syspath_prepend(str(root))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (str(root), os.environ.get("PYTHONPATH")) if p))
    sys.modules.pop("molmo_test_policies", None)
    get_plugins.cache_clear()
    yield SimpleNamespace(marker_dir=markers, site=root)
    sys.modules.pop("molmo_test_policies", None)
    get_plugins.cache_clear()


@pytest.fixture(scope="session")
def small_bench(tmp_path_factory) -> Path:
    """An 8-episode pick benchmark (4 houses x 2) generated into a temp dir."""
    from molmo_lerobot.benchmark.generate import generate_benchmark, write_benchmark

    episodes, metadata = generate_benchmark("pick", 4, 2, seed=7, name="pick_small")
    return write_benchmark(tmp_path_factory.mktemp("bench") / "pick_small", episodes, metadata)


def _eval_config(bench: Path, out: Path, *overrides: str):
    """Composed ``molmo-eval`` config for ``bench`` writing to ``out`` (no progress bar)."""
    from molmo_lerobot.config import compose

    return compose([f"benchmark.path={bench}", f"output_dir={out}", "progress=false", *overrides])


def _outcomes(run_dir: Path) -> list[dict]:
    """The ``episodes.jsonl`` contract fields (plus task type and horizon) of a run, by episode."""
    keys = ("episode_index", "house_index", "task_cls", "success", "success_once", "steps", "seed", "error",
            "task_type", "horizon")
    rows = [json.loads(line) for line in (run_dir / "episodes.jsonl").read_text().splitlines() if line.strip()]
    return [{k: r.get(k) for k in keys} for r in sorted(rows, key=lambda r: r["episode_index"])]


@pytest.fixture
def eval_config():
    """``eval_config(bench, out, *overrides)``: a composed run config (call after ``faulty_policy``)."""
    return _eval_config


@pytest.fixture
def outcomes():
    """``outcomes(run_dir)``: the per-episode outcome fields of a run, sorted by episode."""
    return _outcomes
