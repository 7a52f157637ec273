"""MolmoSpaces' side of tests/parity/test_horizons.py: their eval_main.determine_task_horizon.

``molmo_spaces.evaluation`` imports their whole runner (wandb, torch, ...) at import time; the
function itself needs none of it, so its own source is taken from their installed
``eval_main.py`` and run unchanged.
"""

from __future__ import annotations

import ast
import importlib.util
import logging
from pathlib import Path
from types import SimpleNamespace


def _determine_task_horizon():
    root = Path(next(iter(importlib.util.find_spec("molmo_spaces").submodule_search_locations)))
    source = (root / "evaluation" / "eval_main.py").read_text()
    node = next(n for n in ast.parse(source).body
                if isinstance(n, ast.FunctionDef) and n.name == "determine_task_horizon")
    namespace = {"log": logging.getLogger("eval_main"), "EpisodeSpec": object}
    exec(compile(ast.Module([node], type_ignores=[]), "eval_main.py", "exec"), namespace)
    return namespace["determine_task_horizon"]


def horizons(inputs: dict) -> dict:
    """Per case: their resolved horizon in steps, or the first line of the error they raise."""
    determine_task_horizon = _determine_task_horizon()
    out = []
    for case in inputs["cases"]:
        episodes = [SimpleNamespace(task=task) for task in case["tasks"]]
        try:
            out.append({"steps": determine_task_horizon(episodes, case["override"], case["policy_dt_ms"])})
        except ValueError as exc:
            out.append({"error": str(exc).splitlines()[0]})
    return {"cases": out}
