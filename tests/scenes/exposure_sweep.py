"""Clipped pixels per house and camera at each exposure (issue 36): what render profile v3's exposure is
chosen from.

``python tests/scenes/exposure_sweep.py pick_v2 pick_and_place_v2 next_to_v2 color_v2 open_v2 close_v2``:
for the first episode of every house of each benchmark, at reset, both cameras at 224² under profile v3's
knobs (no shadows, reflections or multisampling) with every light (the headlight included) scaled by each
of :data:`EXPOSURES`; prints one JSON line per house (the share of pixels with every channel ≥ 250 and
the mean value per camera and exposure) and then the worst house and camera per exposure."""

from __future__ import annotations

import dataclasses
import json
import sys

import numpy as np

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing
from molmo_lerobot.sim.render_profile import PROFILES

EXPOSURES = (1.0, 0.9, 0.8, 0.7, 0.6)


def main(names: list[str]) -> None:
    ctx = RunContext.build()
    unscaled = dataclasses.replace(PROFILES["v3"], exposure=1.0)
    ctx = dataclasses.replace(ctx, render_record=unscaled.record())
    rows = []
    for name in names:
        bench = load_benchmark(data_path("benchmarks") / name, ctx.plugins)
        seen = set()
        for i, spec in enumerate(bench.episodes):
            if spec.house_index in seen:
                continue
            seen.add(spec.house_index)
            env = build_env(spec, Timing(), ctx)
            env.reset(0)
            m, head = env.model, env.model.vis.headlight
            base = [m.light_ambient.copy(), m.light_diffuse.copy(), m.light_specular.copy(),
                    np.array(head.ambient), np.array(head.diffuse), np.array(head.specular)]
            row = {"benchmark": name, "episode": i, "house": spec.house_index, "clipped": {}, "mean": {}}
            for e in EXPOSURES:
                m.light_ambient[:], m.light_diffuse[:], m.light_specular[:] = base[0] * e, base[1] * e, base[2] * e
                head.ambient, head.diffuse, head.specular = base[3] * e, base[4] * e, base[5] * e
                for cam in env.camera_names:
                    env._frames.clear()
                    img = env.render(cam)
                    row["clipped"].setdefault(cam, []).append(round(float((img >= 250).all(-1).mean()), 4))
                    row["mean"].setdefault(cam, []).append(round(float(img.mean()), 1))
            env.close()
            rows.append(row)
            print(json.dumps(row), flush=True)
    for k, e in enumerate(EXPOSURES):
        worst = max((r["clipped"][c][k], r["benchmark"], r["house"], c) for r in rows for c in r["clipped"])
        print(f"exposure {e}: worst {worst[0]:.2%} clipped ({worst[1]} house {worst[2]}, {worst[3]})")


if __name__ == "__main__":
    main(sys.argv[1:])
