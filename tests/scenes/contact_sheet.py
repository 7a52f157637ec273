"""Contact sheet (issue 26): exterior and wrist views at reset of 12 v2 episodes beside 12 v1 episodes.

``python tests/scenes/contact_sheet.py docs/contact_sheet_v2_v1.png``: each row shows one v2 episode
(two from each v2 benchmark, from different houses; exterior = DROID's shoulder camera ``exo_camera_1``,
wrist = ``wrist_camera``) and one v1 episode (two from each v1 benchmark; ``exterior`` and ``wrist``),
224² each, as the policy sees them."""

from __future__ import annotations

import sys

import cv2
import numpy as np

from molmo_lerobot.benchmark.load import load_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.paths import data_path
from molmo_lerobot.runner.episode_env import build_env
from molmo_lerobot.sim.env import Timing

V2 = ("pick_v2", "pick_and_place_v2", "next_to_v2", "color_v2", "open_v2", "close_v2")
V1 = ("pick_v1", "pick_and_place_v1", "next_to_v1", "color_v1", "open_v1", "close_v1")


def _views(spec, ctx: RunContext) -> list[np.ndarray]:
    env = build_env(spec, Timing(), ctx)
    try:
        env.reset(spec.seed)
        return [env.render(cam) for cam in sorted(env.camera_names, key=lambda c: "wrist" in c)]
    finally:
        env.close()


def _label(image: np.ndarray, text: str) -> np.ndarray:
    out = image.copy()
    cv2.rectangle(out, (0, 0), (224, 14), (0, 0, 0), -1)
    cv2.putText(out, text[:38], (2, 11), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def main(out: str) -> None:
    ctx = RunContext.build()
    v2 = [load_benchmark(data_path("benchmarks") / name, ctx.plugins).episodes[k * 53] for name in V2 for k in range(2)]
    v1 = [load_benchmark(data_path("benchmarks") / name, ctx.plugins).episodes[k * 7] for name in V1 for k in range(2)]
    rows = []
    for a, b in zip(v2, v1, strict=True):
        left = [_label(img, a.language.task_description) for img in _views(a, ctx)]
        right = [_label(img, b.language.task_description) for img in _views(b, ctx)]
        gap = np.full((224, 12, 3), 255, np.uint8)
        rows.append(np.concatenate([*left, gap, *right], axis=1))
    sheet = np.concatenate(rows, axis=0)
    head = np.full((24, sheet.shape[1], 3), 255, np.uint8)
    cv2.putText(head, "v2: two episodes per v2 benchmark (exterior | wrist)", (4, 17), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(head, "v1: two per v1 benchmark (exterior | wrist)", (460, 17),
                cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    sheet = np.concatenate([head, sheet], axis=0)
    cv2.imwrite(out, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(out, sheet.shape)


if __name__ == "__main__":
    main(sys.argv[1])
