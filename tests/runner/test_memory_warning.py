"""``molmo-eval`` warns, in one line before any worker starts, when its workers would need more memory than the
machine has available (``runner/memory.py``)."""

from __future__ import annotations

import pytest

from eval_runs import evaluate
from molmo_lerobot.runner import evaluate as evaluate_module
from molmo_lerobot.runner.memory import WORKER_GB, benchmark_family, memory_warning


@pytest.mark.parametrize(("benchmark", "suite", "family"), [
    ("pick_v1", None, "v1"), ("pick_v3", None, "v2/v3"), ("close_v2", None, "v2/v3"), ("nav_v1", None, "nav/door"),
    ("door_v1", None, "nav/door"), ("libero_object", "libero", "libero"), ("pusht", "pusht", "pusht"),
    ("my_benchmark", None, "v2/v3")])
def test_each_benchmark_has_a_family(benchmark, suite, family):
    assert benchmark_family(benchmark, suite) == family


def test_the_warning_says_what_fits():
    per_worker = WORKER_GB["v2/v3"][True]
    available = 3.5 * per_worker
    line = memory_warning(8, "v2/v3", True, available)
    assert line is not None and "\n" not in line
    assert f"8 workers x {per_worker:g} GB" in line and "workers=3 fits" in line
    assert memory_warning(3, "v2/v3", True, available) is None
    assert memory_warning(8, "v2/v3", True, None) is None  # the machine does not say: no guess


def test_molmo_eval_warns_before_it_starts(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(evaluate_module, "available_gb", lambda: 0.5)
    res = evaluate("policy=random", "benchmark=pick_v1", "limit=1", "horizon=2", "workers=1",
                   f"output_dir={tmp_path}", "progress=false")
    warnings = [line for line in capsys.readouterr().err.splitlines() if "GB" in line]
    assert warnings == [memory_warning(1, "v1", False, 0.5)]
    assert res.summary["n_errors"] == 0


def test_the_readme_states_each_familys_figures():
    from pathlib import Path

    readme = (Path(__file__).parents[2] / "README.md").read_text()
    for family, (plain, recorded) in WORKER_GB.items():
        assert f"| {family} | {plain:g} GB | {recorded:g} GB |" in readme, family
