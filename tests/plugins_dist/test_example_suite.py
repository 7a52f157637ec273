"""A third-party env suite pip-installed from its own directory (plugins/molmo-example-suite) runs in molmo-eval
with nothing of the core changed: it adds a benchmark kind through the ``molmo_benchmark_kinds`` hook, so
``molmo-bench list`` lists ``dot_reach``, ``molmo-eval benchmark=dot_reach workers=2`` runs, records in its own
layout and resumes, and ``molmo-compare`` compares two of its runs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("hatchling", reason="building the example suite offline needs hatchling in the venv")

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def target(tmp_path_factory) -> Path:
    target = tmp_path_factory.mktemp("site")
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                           "--no-index", "--target", str(target), str(REPO / "plugins" / "molmo-example-suite")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return target


def molmo_eval(target: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """``molmo-eval <args>`` with the suite installed in ``target``."""
    path = os.pathsep.join([str(target), *filter(None, [os.environ.get("PYTHONPATH")])])
    env = dict(os.environ, PYTHONPATH=path, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    code = "import sys; from molmo_lerobot.cli.eval import main; sys.exit(main())"
    return subprocess.run([sys.executable, "-c", code, "progress=false", *args], env=env, capture_output=True,
                          text=True, timeout=300)


def episodes(run: Path) -> list[tuple[int, bool, int]]:
    rows = [json.loads(line) for line in (run / "episodes.jsonl").read_text().splitlines()]
    return sorted((r["episode_index"], r["success"], r["steps"]) for r in rows)


def test_a_pip_installed_suite_lists_runs_records_resumes_and_compares(target, tmp_path, monkeypatch, capsys):
    from molmo_lerobot.cli import bench, compare

    monkeypatch.syspath_prepend(str(target))  # molmo-bench and molmo-compare in this process find it too
    assert bench.main(["list"]) == 0
    listed = capsys.readouterr().out
    row = next(line.split() for line in listed.splitlines() if line.startswith("dot_reach"))
    assert row[1:7] == ["env", "suite", "dot", "2", "per", "task"]
    assert "env suite dot: molmo-example-suite 0.1.0 (Apache-2.0)" in listed

    whole, resumed = tmp_path / "whole", tmp_path / "resumed"
    ran = molmo_eval(target, "policy=random", "benchmark=dot_reach", "workers=2", "record=true", f"output_dir={whole}")
    assert ran.returncode == 0, ran.stderr[-3000:]
    results = json.loads((whole / "results.json").read_text())
    assert results["n_episodes"] == 6 and sorted(results["per_task"]) == ["dot/left", "dot/middle", "dot/right"]
    info = json.loads((whole / "dataset" / "meta" / "info.json").read_text())
    assert info["robot_type"] == "point" and info["total_episodes"] == 6
    assert {"action", "next.success", "observation.image", "observation.state"} <= set(info["features"])

    first = molmo_eval(target, "policy=random", "benchmark=dot_reach", "workers=2", "limit=3", f"output_dir={resumed}")
    assert first.returncode == 0, first.stderr[-3000:]
    rest = molmo_eval(target, f"output_dir={resumed}", "resume=true", "limit=6")
    assert rest.returncode == 0, rest.stderr[-3000:]
    assert episodes(resumed) == episodes(whole)

    assert compare.main([str(whole), str(resumed), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n_shared"] == 6 and report["overall"]["only_a"] == report["overall"]["only_b"] == 0
    assert sorted(report["per_task"]) == ["dot/left", "dot/middle", "dot/right"]
