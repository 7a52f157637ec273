"""Contact sheet (issue 27): door_v1's cameras at the start and at success, pushing and pulling.

``python tests/doors/contact_sheet.py docs/contact_sheet_door_v1.png``: each row is one door_v1
episode played by the scripted expert (two push, two pull, different houses): the head camera and
the wrist camera at reset, then both at the first step the door counts as open, 224² each, as the
policy sees them."""

from __future__ import annotations

import sys

import cv2
import numpy as np

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.policies.base import EpisodeContext
from molmo_lerobot.policies.scripted import ScriptedExpert
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.runner.plan import resolve_horizon
from molmo_lerobot.sim.env import Timing

CAMERAS = ("head_camera", "wrist_camera")


def _row(spec, ctx: RunContext) -> np.ndarray:
    timing = Timing()
    task_type = ctx.plugins.task_type(spec.task_name)
    env = build_env(spec, timing, ctx)
    try:
        env.reset(spec.seed)
        task = task_type.create(spec, env)
        start = [env.render(c) for c in CAMERAS]
        policy = ScriptedExpert({})
        policy.reset(EpisodeContext(spec=spec, episode_index=0, seed=spec.seed, prompt=spec.prompt,
                                    move_groups=dict(env.move_groups), policy_dt_s=timing.policy_dt_s, env=env,
                                    catalog=ctx.catalog, expert=ctx.plugins.expert(task_type.name)))
        for _ in range(resolve_horizon(None, spec.task, task_type.default_horizon_sec, timing.policy_dt_ms)):
            chunk = policy.act(env.observe(False))
            for k in range(len(chunk["arm"])):
                env.step({g: v[k] for g, v in chunk.items()})
                if task.success():
                    break
            if task.success():
                break
        end = [env.render(c) for c in CAMERAS]
    finally:
        env.close()
    tiles = [cv2.resize(img, (224, 224)) for img in (*start, *end)]
    row = np.hstack(tiles)
    label = f"house {spec.house_index}: {spec.prompt} (start | open {task.openness():.2f})"
    cv2.putText(row, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return row


def main(out: str) -> None:
    ctx = RunContext.build()
    bench = load_benchmark(data_path("benchmarks") / "door_v1", ctx.plugins)
    rows, seen = [], {"Push the door open": 0, "Pull the door open": 0}
    for spec in bench.episodes:
        if seen[spec.prompt] < 2 and all(spec.house_index != r[0] for r in rows):
            seen[spec.prompt] += 1
            rows.append((spec.house_index, _row(spec, ctx)))
    cv2.imwrite(out, cv2.cvtColor(np.vstack([r for _, r in rows]), cv2.COLOR_RGB2BGR))
    print(out)


if __name__ == "__main__":
    main(sys.argv[1])
