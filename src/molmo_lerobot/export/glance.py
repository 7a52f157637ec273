"""What ``report.html`` needs from each rollout, gathered in the worker during the one rollout.

:class:`GlanceRecorder` runs on every run (``record=true`` or not). Per episode it

* renders the exterior camera at the first and the last step only (``wants_images_at``) and
  saves both side by side, small, as ``thumbnails/<episode>.jpg``;
* notes the first step after which the task succeeded (``first_success_step``) and the
  target object's category (``object_category``),

and puts them in the episode result's ``extra`` (so they reach ``episodes.jsonl``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from molmo_lerobot.fileio import atomic_write
from molmo_lerobot.recording import EpisodeInfo, Recorder, RecorderFactory
from molmo_lerobot.results import EpisodeResult

if TYPE_CHECKING:
    from molmo_lerobot.assets.catalog import AssetCatalog

THUMBNAILS_DIR = "thumbnails"


def thumbnail_path(episode_index: int) -> str:
    """The thumbnail of an episode, relative to the run's output directory."""
    return f"{THUMBNAILS_DIR}/{int(episode_index):06d}.jpg"


def exterior_camera(names: list[str]) -> str | None:
    """The camera a person would look at: one named *exterior*, else the first that is not a wrist camera."""
    for pick in (lambda n: "exterior" in n, lambda n: "wrist" not in n, lambda n: True):
        for n in names:
            if pick(n.lower()):
                return n
    return None


def object_category(uid: str | None, catalog: AssetCatalog | None) -> str | None:
    """The category ``catalog`` gives ``uid``; else the uid without a trailing number or hash."""
    if not uid:
        return None
    try:
        category = catalog.annotation(uid).get("category") if catalog is not None else None
        if category:
            return str(category)
    except Exception:  # an asset no installed library knows: fall back on its name
        pass
    return re.sub(r"([_-](\d+|[0-9a-f]{6,}))+$", "", uid).lower() or uid


@dataclass
class GlanceRecorderFactory(RecorderFactory):
    """Picklable recipe for :class:`GlanceRecorder`; ``width`` is the width of one thumbnail frame."""

    width: int = 160

    def make(self, worker_id: str, output_dir: Path) -> GlanceRecorder:
        return GlanceRecorder(Path(output_dir), self.width)


class GlanceRecorder(Recorder):
    """Thumbnails (first and last exterior frame), first success step and object category per episode."""

    wants_images = False

    def __init__(self, output_dir: Path, width: int) -> None:
        self.output_dir = output_dir
        self.width = width
        self._info: EpisodeInfo | None = None
        self._camera: str | None = None
        self._frames: list[np.ndarray] = []
        self._step = 0
        self._first_success: int | None = None

    def wants_images_at(self, step: int, horizon: int) -> bool:
        return step in (0, horizon - 1)

    def start_episode(self, info: EpisodeInfo) -> None:
        self._info, self._camera = info, exterior_camera(list(info.camera_names))
        self._frames, self._step, self._first_success = [], 0, None

    def record_step(self, obs: dict[str, Any], action: Any, reward: float | None, success: bool, done: bool) -> None:
        info = self._info
        image = (obs.get("images") or {}).get(self._camera) if self._camera else None
        if info is not None and image is not None and self._step in (0, info.horizon - 1):
            self._frames.append(self._small(np.asarray(image)))
        if success and self._first_success is None:
            self._first_success = self._step + 1  # success holds after this step's action
        self._step += 1

    def end_episode(self, result: EpisodeResult) -> None:
        info = self._info
        if info is None:
            return
        result.extra["first_success_step"] = self._first_success
        result.extra["object_category"] = object_category(info.extra.get("object"), info.catalog)
        if self._frames:
            result.extra["thumbnail"] = self._save(result.episode_index)
        self._info, self._frames = None, []

    def _small(self, image: np.ndarray) -> np.ndarray:
        import cv2

        h, w = image.shape[:2]
        height = max(1, round(h * self.width / w))
        return cv2.resize(np.ascontiguousarray(image[..., :3]), (self.width, height), interpolation=cv2.INTER_AREA)

    def _save(self, episode_index: int) -> str:
        """First | last frame side by side (a 2 px gap), written atomically."""
        import cv2

        frames = self._frames
        gap = np.full((frames[0].shape[0], 2, 3), 255, np.uint8)
        strip = np.concatenate([frames[0], gap, frames[-1]], axis=1) if len(frames) > 1 else frames[0]
        rel = thumbnail_path(episode_index)
        ok, data = cv2.imencode(".jpg", cv2.cvtColor(strip, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 85])
        if not ok:
            raise RuntimeError(f"could not encode the thumbnail of episode {episode_index}")
        atomic_write(self.output_dir / rel, data.tobytes(), root=self.output_dir)
        return rel
