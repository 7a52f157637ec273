"""Content hashes of the policy checkpoints and robots a run uses, so a run knows exactly which weights
and which robot it scored.

``run.json`` and ``results.json`` record them under ``policy_checkpoint`` and ``robots``; ``resume=true``
refuses to continue a run whose checkpoint changed since (a retrained ``checkpoints/last``
keeps its path but not its content) or whose robots differ, and ``molmo-compare`` refuses runs of
different robots.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

from molmo_lerobot.plugins import PluginError
from molmo_lerobot.suites.benchmark import SUITE_KEY, SUITES, SuiteBenchmark

if TYPE_CHECKING:
    from molmo_lerobot.benchmark.load import Benchmark
    from molmo_lerobot.context import RunContext
    from molmo_lerobot.runner.plan import EpisodePlan

#: policy config keys that name a checkpoint (a file or a ``save_pretrained`` directory)
CHECKPOINT_KEYS = ("path", "checkpoint", "checkpoint_path", "pretrained_path")


def checkpoint_sha256(path: Path) -> dict[str, Any]:
    """sha256 over every file under ``path`` (weights, config, processors): relative name, size, content.

    Symlinks are followed (``checkpoints/last``), so the hash is the content the policy loads.
    """
    path = Path(path).expanduser()
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    total = hashlib.sha256()
    n_bytes = 0
    for f in files:
        with open(f, "rb") as fh:
            digest = hashlib.file_digest(fh, "sha256").hexdigest()
        size = f.stat().st_size
        n_bytes += size
        rel = f.name if f == path else f.relative_to(path).as_posix()
        total.update(f"{rel}\0{size}\0{digest}\n".encode())
    return {"path": str(path.resolve()), "sha256": total.hexdigest(), "n_files": len(files), "bytes": n_bytes}


def policy_checkpoints(policy_cfg: dict[str, Any]) -> dict[str, Any] | None:
    """``{config key: checkpoint_sha256(...)}`` for each local checkpoint the policy config names.

    A value that is not a local path (a Hub repo id, a server address) is recorded as given with
    ``sha256: null``: its content cannot be checked here. None when the policy names no checkpoint.
    """
    out: dict[str, Any] = {}
    for key in CHECKPOINT_KEYS:
        value = policy_cfg.get(key)
        if not isinstance(value, str) or not value or value == "???":
            continue
        local = Path(value).expanduser()
        out[key] = checkpoint_sha256(local) if local.exists() else {"path": value, "sha256": None}
    return out or None


def plan_robot(plan: EpisodePlan) -> str | None:
    """The robot episode ``plan`` runs: its spec's ``robot.robot_name`` (after the run's overrides:
    ``robot.name``), an env suite's own robot (LIBERO's Panda), ``None`` for none (PushT's pusher)."""
    if SUITE_KEY in plan.spec:
        return SUITES[plan.spec[SUITE_KEY]].robot
    robot = plan.spec.get("robot")
    name = robot.get("robot_name") if isinstance(robot, dict) else None
    return name if isinstance(name, str) else None


def robots_of(run: RunContext, bench: Benchmark | SuiteBenchmark,
              plans: dict[int, EpisodePlan]) -> list[dict[str, Any]]:
    """The robots the run's episodes run (``run.json``'s and ``results.json``'s ``robots``): each one's
    name, version (the distribution that provides it) and ``sha256`` of its model as built for this run
    (:meth:`~molmo_lerobot.robots.base.RobotType.model_sha256`: MolmoSpaces' model where installed
    differs from the registry-built one).
    An env suite builds its own robot in its env: name only."""
    out = []
    for name in sorted({ran for plan in plans.values() if (ran := plan_robot(plan)) is not None}):
        if isinstance(bench, SuiteBenchmark):
            out.append({"name": name, "version": None, "sha256": None})
            continue
        try:
            provider = run.plugins.provider("robot", name)
            robot = run.plugins.robot(name).configured(run.settings)
            sha256 = robot.model_sha256()
        except (PluginError, OSError, ValueError):  # its episodes are recorded as errors, saying why
            continue
        out.append({"name": name, "version": f"{provider.distribution} {provider.version}", "sha256": sha256})
    return out
