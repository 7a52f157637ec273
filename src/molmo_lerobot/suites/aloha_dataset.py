"""LeRobot's ALOHA sim dataset layout (``lerobot/aloha_sim_insertion_human``,
``lerobot/aloha_sim_transfer_cube_human``): how an ALOHA episode is recorded with ``record=true``.

Those datasets (their ``meta/info.json``, codebase v3.0) hold, per frame, exactly these features:

* ``observation.images.top``: video ``(480, 640, 3)``, names ``height, width, channel`` (the top camera);
* ``observation.state`` and ``action``: float32 ``(14,)``, names ``{"motors": [left_waist … right_gripper]}``:
  each arm's six joints and its gripper, left arm first;
* ``next.done``: bool ``(1,)``, no names: whether the episode ended after the frame's action;
* ``fps`` 50 (gym-aloha's control rate) and ``robot_type`` ``aloha``.

No ``next.reward``/``next.success`` (their datasets have none, and LeRobot merges only equal features).
"""

from __future__ import annotations

from molmo_lerobot.dataset_layout import DatasetLayout, Vector
from molmo_lerobot.suites.aloha import ACTION_DIM, CONTROL_HZ, IMAGE_HEIGHT, IMAGE_WIDTH, MOVE_GROUP, STATE_DIM

ROBOT_TYPE = "aloha"
#: the 14 entries of state and action, as the datasets name them
MOTORS = [f"{arm}_{joint}" for arm in ("left", "right")
          for joint in ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate", "gripper")]


def aloha_layout() -> DatasetLayout:
    """The frame schema of an ALOHA recording (gym-aloha's frames are always 480 × 640)."""
    return DatasetLayout(
        image_size=(IMAGE_HEIGHT, IMAGE_WIDTH),
        cameras=(("top", "observation.images.top", "the top camera over the table"),),
        move_group=MOVE_GROUP,
        state=Vector("observation.state", STATE_DIM, {"motors": MOTORS},
                     "the two ViperX arms' joint positions: per arm (left first) six joints in radians and the "
                     "gripper normalised 0 closed … 1 open"),
        action=Vector("action", ACTION_DIM, {"motors": MOTORS}, "the same 14 joints' absolute position targets"),
        robot_type=ROBOT_TYPE, fps=CONTROL_HZ, step_hz=CONTROL_HZ, outcomes=("next.done",),
        simulator="gym-aloha's bimanual ViperX scenes (ACT's sim tasks), simulated in MuJoCo through dm-control; "
                  "the images are MuJoCo renders")
