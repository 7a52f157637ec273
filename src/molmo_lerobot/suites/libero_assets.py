"""Check the registry's LIBERO asset tree against what LIBERO's own code loads: run with the LIBERO venv's
Python (``python -m molmo_lerobot.suites.libero_assets [SUITE ...]``, all five suites by default).

For every task of each suite LIBERO's ``ControlEnv`` builds and compiles the task's MuJoCo model from its BDDL
file (scene, fixtures, objects, robot; no renderer), which fails on any missing or unreadable mesh, texture or
included XML. The compiled model's MJCF names every file it read; prints one JSON line: tasks built, those that
failed (and why), the asset files read, and the registry's files that no task reads.
"""

from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path

SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10", "libero_90")
_FILE_ATTR = re.compile(r'\bfile="([^"]+)"')


def check(suites: tuple[str, ...] = SUITES) -> dict:
    from libero.libero import benchmark, get_assets_path, get_libero_path
    from libero.libero.envs.env_wrapper import ControlEnv

    assets = Path(get_assets_path()).resolve()
    read: set[str] = set()
    built, failed = 0, {}
    for suite_name in suites:
        suite = benchmark.get_benchmark_dict()[suite_name]()
        for i in range(suite.get_num_tasks()):
            task = suite.get_task(i)
            bddl = os.path.join(get_libero_path("bddl_files"), task.problem_folder, task.bddl_file)
            try:
                env = ControlEnv(bddl, has_offscreen_renderer=False, use_camera_obs=False)
            except Exception as exc:  # a missing file fails the model's compilation: record, go on
                failed[f"{suite_name}/{i}"] = f"{type(exc).__name__}: {exc}"[:300]
                continue
            for name in _FILE_ATTR.findall(env.sim.model.get_xml()):
                path = Path(name).resolve()
                if path.is_relative_to(assets):
                    read.add(path.relative_to(assets).as_posix())
            env.close()
            built += 1
    shipped = {p.relative_to(assets).as_posix() for p in assets.rglob("*")
               if p.is_file() and p.suffix.lower() in {".obj", ".msh", ".stl", ".png", ".jpg"}}
    unread = shipped - read
    return {"assets": str(assets), "tasks_built": built, "failed": failed, "files_read": len(read),
            "files_missing": sorted(read - shipped), "files_shipped": len(shipped),
            "unread_top_dirs": sorted({f.split("/")[0] for f in unread}), "unread": len(unread)}


if __name__ == "__main__":
    print(json.dumps(check(tuple(sys.argv[1:]) or SUITES)))
