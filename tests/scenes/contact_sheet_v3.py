"""Contact sheet (issue 36): the same 12 v2 episodes at reset through render profile v2 (left) and v3 (right).

``python tests/scenes/contact_sheet_v3.py docs/contact_sheet_v3_v2.png``: each row is one episode (two from
each v2 benchmark, the episodes of ``docs/contact_sheet_v2_v1.png``), exterior (``exo_camera_1``) and wrist
(``wrist_camera``), 224² each, as the policy sees them; each label gives the share of clipped pixels
(every channel ≥ 250)."""

from __future__ import annotations

import dataclasses
import sys

import cv2
import numpy as np
from contact_sheet import V2, _label

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing
from molmo_lerobot.sim.render_profile import resolve_profile


def _views(spec, ctx: RunContext, profile: str) -> list[np.ndarray]:
    ctx = dataclasses.replace(ctx, render_record=resolve_profile(profile).record())
    env = build_env(spec, Timing(), ctx)
    try:
        env.reset(spec.seed)
        return [env.render(cam).copy() for cam in sorted(env.camera_names, key=lambda c: "wrist" in c)]
    finally:
        env.close()


def main(out: str) -> None:
    ctx = RunContext.build()
    episodes = [load_benchmark(data_path("benchmarks") / name, ctx.plugins).episodes[k * 53] for name in V2
                for k in range(2)]
    rows = []
    for spec in episodes:
        cells = {p: [_label(img, f"{p} h{spec.house_index} clipped {(img >= 250).all(-1).mean():.1%}")
                     for img in _views(spec, ctx, p)] for p in ("v2", "v3")}
        gap = np.full((224, 12, 3), 255, np.uint8)
        rows.append(np.concatenate([*cells["v2"], gap, *cells["v3"]], axis=1))
    sheet = np.concatenate(rows, axis=0)
    head = np.full((24, sheet.shape[1], 3), 255, np.uint8)
    for x, text in ((4, "render profile v2 (exterior | wrist)"), (460, "render profile v3 (exterior | wrist)")):
        cv2.putText(head, text, (x, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    sheet = np.concatenate([head, sheet], axis=0)
    cv2.imwrite(out, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(out, sheet.shape)


if __name__ == "__main__":
    main(sys.argv[1])
