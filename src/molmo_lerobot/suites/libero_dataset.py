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

No ``next.success``/``next.done``/``eval.*`` columns (their datasets have none, and LeRobot merges only equal
features). The cameras are video (``lerobot/libero``'s storage). The images are the ones the policy saw, at
``benchmark.image_size``: 256 makes a recording that merges with LeRobot's datasets; ``lerobot-eval``'s default
360 records 360² frames.
"""

from __future__ import annotations

from molmo_lerobot.dataset_layout import DatasetLayout, Vector
from molmo_lerobot.suites.libero import ACTION_DIM, CONTROL_HZ, MOVE_GROUP

#: the datasets' declared frame rate (LIBERO steps at 20 Hz; each frame is one step)
DATASET_FPS = 10
ROBOT_TYPE = "panda"
STATE_DIM = 8
#: the image size of LeRobot's LIBERO datasets
DATASET_IMAGE_SIZE = 256


def libero_layout(image_size: int) -> DatasetLayout:
    """The frame schema of a LIBERO recording at ``image_size``²."""
    return DatasetLayout(
        image_size=image_size,
        cameras=(("image", "observation.images.image", "the agent-view camera, turned 180° as LeRobot does"),
                 ("image2", "observation.images.image2", "the wrist camera, turned 180°")),
        move_group=MOVE_GROUP,
        state=Vector("observation.state", STATE_DIM, ["state"],
                     "the Panda's 8-D end-effector state: position (3), orientation as an axis-angle (3), the two "
                     "finger positions (2)"),
        action=Vector("action", ACTION_DIM, ["actions"],
                      "the 7-D delta end-effector command: position (3) and axis-angle (3) deltas, gripper (-1 open "
                      "… +1 closed)"),
        robot_type=ROBOT_TYPE, fps=DATASET_FPS, step_hz=CONTROL_HZ,
        simulator="LIBERO's scenes, simulated in MuJoCo through robosuite 1.4; the images are MuJoCo renders")
