"""LeRobot's LIBERO dataset layout: how a LIBERO episode is recorded with ``record=true``.

LeRobot's LIBERO training sets (``HuggingFaceVLA/libero``, and ``lerobot/libero``, the same schema with the
cameras as MP4) hold, per frame, exactly these features (their ``meta/info.json``, codebase v3.0):

* ``observation.images.image`` (agent view) and ``observation.images.image2`` (wrist): ``(256, 256, 3)``,
  names ``height, width, channel``, turned 180° from LIBERO's renders (what ``LiberoProcessorStep`` does);
* ``observation.state``: float32 ``(8,)``, named ``["state"]``: end-effector position, axis-angle, two
  finger positions;
* ``action``: float32 ``(7,)``, named ``["actions"]``: delta end-effector position and axis-angle, gripper;
* ``fps`` 10 and ``robot_type`` ``panda``, one frame per 20 Hz control step of LIBERO (the declared rate is
  the datasets' own; the real one, 20 Hz, is the recording's ``meta/eval/info.json`` ``fps_exact``).

LeRobot's ``aggregate_datasets`` merges only datasets whose features, fps and robot type are all equal, so a
recording in this layout has nothing else: no ``next.success``/``next.done``/``eval.*`` columns (the eval
record of each episode is in ``meta/eval/episodes.jsonl``, as for every recording). The cameras are video
(``lerobot/libero``'s storage). The images are the ones the policy saw, at ``benchmark.image_size``: 256 makes a
recording that merges with LeRobot's datasets; ``lerobot-eval``'s default 360 records 360² frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from molmo_lerobot.features import FeatureError
from molmo_lerobot.suites.libero import ACTION_DIM, CONTROL_HZ, MOVE_GROUP

if TYPE_CHECKING:
    from molmo_lerobot.recording import EpisodeInfo

#: the datasets' declared frame rate (LIBERO steps at 20 Hz; each frame is one step)
DATASET_FPS = 10
ROBOT_TYPE = "panda"
STATE_DIM = 8
#: the image size of LeRobot's LIBERO datasets
DATASET_IMAGE_SIZE = 256
#: our policy observation's camera -> LeRobot's LIBERO dataset feature
CAMERA_FEATURES = {"image": "observation.images.image", "image2": "observation.images.image2"}


@dataclass(frozen=True)
class LiberoDatasetLayout:
    """The frame schema of a LIBERO recording at ``image_size``² (the ``FrameLayout`` interface the
    recorder writes with: ``features``, ``frame``, ``robot_type``, ``fps``)."""

    image_size: int
    robot_type: str = ROBOT_TYPE
    fps: int = DATASET_FPS
    #: the real rate of the frames (one per control step)
    step_hz: float = CONTROL_HZ

    def features(self) -> dict[str, dict[str, Any]]:
        """``LeRobotDataset.create``'s ``features``."""
        image = {"dtype": "video", "shape": (self.image_size, self.image_size, 3),
                 "names": ["height", "width", "channel"]}
        return {**{feature: dict(image) for feature in CAMERA_FEATURES.values()},
                "observation.state": {"dtype": "float32", "shape": (STATE_DIM,), "names": ["state"]},
                "action": {"dtype": "float32", "shape": (ACTION_DIM,), "names": ["actions"]}}

    def frame(self, obs: dict[str, Any], action: dict[str, Any], reward: float | None, success: bool,
              done: bool, task: str, info: EpisodeInfo) -> dict[str, Any]:
        """One ``add_frame`` dict of a suite session's observation (:func:`~molmo_lerobot.suites.libero.
        policy_observation`) and the 7-D action taken on it; raises ``FeatureError`` naming the misfit."""
        shape = (self.image_size, self.image_size, 3)
        frame: dict[str, Any] = {}
        for camera, feature in CAMERA_FEATURES.items():
            image = np.asarray((obs.get("images") or {}).get(camera))
            if image.shape != shape or image.dtype != np.uint8:
                raise FeatureError(f"{feature}: got {image.dtype} {image.shape}, expected uint8 {shape}")
            frame[feature] = image
        frame["observation.state"] = _vector((obs.get("qpos") or {}).get(MOVE_GROUP), STATE_DIM, "observation.state")
        frame["action"] = _vector(action.get(MOVE_GROUP), ACTION_DIM, "action")
        frame["task"] = task
        return frame


def _vector(value: Any, size: int, feature: str) -> np.ndarray:
    if value is None:
        raise FeatureError(f"{feature}: move group {MOVE_GROUP!r} missing")
    out = np.asarray(value, dtype=np.float32).reshape(-1)
    if out.size != size:
        raise FeatureError(f"{feature}: {out.size} values, expected {size}")
    return out
