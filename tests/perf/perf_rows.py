"""What the throughput tables under tests/perf/ share: a run's wall-clock and start-up-free episode
rates, the policy server's statistics when the run served its policy, appending rows to
``runs/perf.jsonl``, timing a command or a ``molmo-eval`` run in a fresh process, and a policy plugin
that reads every camera image (``policy=image_scripted``)."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

from molmo_lerobot.serving.run_server import STATS_FILE


def run_rates(res: Any, workers: int, out: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """The row for run ``res`` of ``workers`` workers written to ``out``, and its server stats ({} if unserved).

    Excluding start-up divides the episodes by the time workers spent inside episodes (their summed
    ``duration_s`` over the worker count), so imports, model loads and scene builds are left out."""
    n = len(res.episodes)
    wall = res.summary["wall_time_s"]
    busy = sum(e.duration_s or 0.0 for e in res.episodes) / workers
    stats = json.loads((out / STATS_FILE).read_text()) if (out / STATS_FILE).exists() else {}
    return {"workers": workers, "episodes": n, "wall_s": round(wall, 2), "eps_per_min": round(60 * n / wall, 2),
            "eps_per_min_excl_startup": round(60 * n / busy, 2) if busy else None,
            "errors": res.summary["n_errors"]}, stats


def append_rows(benchmark: str, rows: list[dict[str, Any]], **common: Any) -> None:
    """Append each row to ``runs/perf.jsonl`` as ``{"benchmark": benchmark, **common, **row}``."""
    Path("runs").mkdir(exist_ok=True)
    with open("runs/perf.jsonl", "a") as f:
        for r in rows:
            f.write(json.dumps({"benchmark": benchmark, **common, **r}) + "\n")



def timed(cmd: list[str], env: dict[str, str]) -> tuple[float, float, str]:
    """Wall seconds, CPU seconds (the process and every descendant it reaped) and stdout of ``cmd``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert out.returncode == 0, out.stderr[-2000:]
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), out.stdout


def eval_run(args: list[str], out: Path, env: dict[str, str]) -> tuple[float, float, list[dict[str, Any]]]:
    """``molmo-eval ARGS output_dir=OUT progress=false`` in a fresh process: its wall and CPU seconds
    (:func:`timed`) and its ``episodes.jsonl`` records, none of which may be an error."""
    wall, cpu, _ = timed([sys.executable, "-m", "molmo_lerobot.cli.eval", *args, f"output_dir={out}",
                          "progress=false"], env)
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert all(r["error"] is None for r in rows), [r["error"] for r in rows]
    return wall, cpu, rows

#: Source of a policy plugin that consumes images: the scripted expert, reading every pixel of both cameras.
PLUGIN = textwrap.dedent('''
    """Perf-only policy: the scripted expert that reads both camera images at every call."""

    from pathlib import Path

    from molmo_lerobot import hookimpl
    from molmo_lerobot.policies.base import PolicyType
    from molmo_lerobot.policies.scripted import ScriptedExpert


    class ImageScripted(ScriptedExpert):
        needs_images = True

        def act(self, obs):
            images = obs["images"]
            if len(images) != 2 or any(im.shape != (224, 224, 3) for im in images.values()):
                raise ValueError(f"expected two 224x224 cameras, got {[im.shape for im in images.values()]}")
            self.checksum = sum(int(im.sum(dtype="uint64")) for im in images.values())
            return super().act(obs)


    @hookimpl
    def molmo_policies():
        return [PolicyType("image_scripted", ImageScripted, "scripted expert that reads both images (perf)")]


    @hookimpl
    def molmo_config_dirs():
        return [str(Path(__file__).parent / "conf")]
''')


def image_policy_env(root: Path, chunk: int) -> dict[str, str]:
    """Environment for subprocesses with the ``molmo_perf_policies`` distribution (``policy=image_scripted``,
    ``chunk`` actions per call) installed under ``root`` and on ``PYTHONPATH``."""
    pkg = root / "molmo_perf_policies"
    (pkg / "conf" / "policy").mkdir(parents=True)
    (pkg / "__init__.py").write_text(PLUGIN)
    (pkg / "conf" / "policy" / "image_scripted.yaml").write_text(f"name: image_scripted\nchunk: {chunk}\n")
    info = root / "molmo_perf_policies-0.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: molmo-perf-policies\nVersion: 0.0\n")
    (info / "entry_points.txt").write_text("[molmo_lerobot]\nmolmo_perf_policies = molmo_perf_policies\n")
    path = os.pathsep.join(p for p in (str(root), os.environ.get("PYTHONPATH")) if p)
    return dict(os.environ, PYTHONPATH=path, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
