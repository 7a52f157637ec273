"""Adding a task type is one plugin package: a toy task distribution with its own spec model.

``molmo_toy_task`` is written into a temporary directory as a module plus a ``*.dist-info``
whose entry point (group ``molmo_lerobot``) names it, and reached through ``PYTHONPATH``
only; nothing in ``src/`` knows it. Its spec model has a field no built-in task has
(``wait_sec``, validated ``0 < wait_sec <= 5``, default 0.5); the task succeeds once
``wait_sec`` of simulated time has passed, and the plugin brings the expert
``policy=scripted`` plays for it. A benchmark file of it validates, runs end to end through
``molmo-eval``, and a bad ``wait_sec`` is one line naming the file, episode and field.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from molmo_lerobot.paths import data_path

MODULE = textwrap.dedent('''\
    """Toy task plugin: wait ``task.wait_sec`` seconds of simulated time (with a do-nothing expert)."""

    import numpy as np
    from pydantic import Field

    from molmo_lerobot import hookimpl
    from molmo_lerobot.benchmark.schema import BaseTaskSpec
    from molmo_lerobot.policies.base import Policy, PolicyType
    from molmo_lerobot.tasks.base import Task, TaskType


    class WaitTaskSpec(BaseTaskSpec):
        pickup_obj_name: str
        wait_sec: float = Field(default=0.5, gt=0, le=5.0)


    class WaitTask(Task[WaitTaskSpec]):
        def __init__(self, spec: WaitTaskSpec, env):
            env.body_id(spec.pickup_obj_name, "task.pickup_obj_name")
            self.spec, self.env, self.wait_sec, self.start = spec, env, spec.wait_sec, None

        def setup(self):
            self.start = float(self.env.data.time)

        def success(self):
            return float(self.env.data.time) - self.start >= self.wait_sec


    class WaitTaskType(TaskType[WaitTaskSpec]):
        name = "toy_wait"
        aliases = ("molmo_toy_task.WaitTask",)
        spec_model = WaitTaskSpec
        default_horizon_sec = 1.0

        def thresholds(self, spec):
            return {"wait_sec": self.task_spec(spec).wait_sec}

        def create(self, spec, env):
            return WaitTask(self.task_spec(spec), env)


    class StillExpert(Policy):
        needs_images = False

        def __init__(self, config):
            self.groups = {}

        def reset(self, ctx):
            self.groups = dict(ctx.move_groups)

        def act(self, obs):
            return {g: np.asarray(obs["qpos"][g], dtype=np.float64)[None] if g != "gripper" else np.zeros((1, n))
                    for g, n in self.groups.items()}


    @hookimpl
    def molmo_task_types():
        return [WaitTaskType()]


    @hookimpl
    def molmo_experts():
        return [PolicyType(name="toy_wait", factory=StillExpert, description="hold still")]
''')


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The toy distribution, installed into a directory that only ``PYTHONPATH`` names."""
    root = tmp_path_factory.mktemp("site")
    (root / "molmo_toy_task.py").write_text(MODULE)
    info = root / "molmo_toy_task-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: molmo-toy-task\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[molmo_lerobot]\ntoy_wait = molmo_toy_task\n")
    return root


def _env(site: Path) -> dict[str, str]:
    path = os.pathsep.join(p for p in (str(site), os.environ.get("PYTHONPATH")) if p)
    return dict(os.environ, PYTHONPATH=path, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))


def _bench(tmp_path: Path, *wait_sec: float | None) -> Path:
    """One toy episode per ``wait_sec`` (``None``: field left out) on the scenes of ``pick_v1``."""
    picks = json.loads((data_path("benchmarks") / "pick_v1" / "benchmark.json").read_text())
    episodes = []
    for pick, wait in zip(picks, wait_sec, strict=False):
        task = {"task_cls": "molmo_toy_task.WaitTask", "robot_base_pose": pick["task"]["robot_base_pose"],
                "pickup_obj_name": pick["task"]["pickup_obj_name"], "task_horizon_sec": 1.0}
        if wait is not None:
            task["wait_sec"] = wait
        episodes.append({**pick, "task": task, "language": {"task_description": "wait"}})
    out = tmp_path / "toy_bench"
    out.mkdir()
    (out / "benchmark.json").write_text(json.dumps(episodes))
    return out


def _run(site: Path, module: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", f"molmo_lerobot.cli.{module}", *args], env=_env(site),
                          capture_output=True, text=True, timeout=600)


def test_toy_task_benchmark_validates_and_runs_end_to_end(site, tmp_path):
    bench = _bench(tmp_path, None, 3.0)  # the model's default 0.5 s is reached in 1 s, 3 s is not
    checked = _run(site, "bench", "validate", str(bench))
    assert checked.returncode == 0, checked.stderr
    assert "tasks      molmo_toy_task.WaitTask (2)" in checked.stdout
    assert "schema and installed plugins: ok" in checked.stdout

    out = tmp_path / "run"
    proc = _run(site, "eval", "policy=scripted", f"benchmark.path={bench}", f"output_dir={out}", "progress=false")
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    assert results["n_episodes"] == 2 and results["n_errors"] == 0
    assert results["thresholds"]["toy_wait"] == {"wait_sec": 0.5, "horizon_steps": [15]}  # the model's default
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert [(r["task_type"], r["success"], r["steps"], r["error"]) for r in rows] == [
        ("toy_wait", True, 15, None), ("toy_wait", False, 15, None)]


def test_bad_toy_field_is_one_line_naming_file_episode_and_field(site, tmp_path):
    bench = _bench(tmp_path, 1.0, -2.0)
    proc = _run(site, "bench", "validate", str(bench))
    assert proc.returncode == 2
    lines = proc.stderr.splitlines()
    assert lines[0] == (f"{bench / 'benchmark.json'}: episode 1: field task.wait_sec: "
                        "Input should be greater than 0 (got -2.0)"), proc.stderr
    assert lines[1:] == ["molmo-bench: 1 problem in 1 episode"]
