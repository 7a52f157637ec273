"""LeRobot's MetaWorld dataset layout (``lerobot/metaworld_mt50``): how a MetaWorld episode is recorded with
``record=true``.

``lerobot/metaworld_mt50`` (codebase v3.0; read from its published ``meta/info.json``, not from LeRobot's code, which
has no writer for it) holds per frame ``observation.image`` (480², LeRobot's flipped ``corner2`` render),
``observation.state`` float32 ``(4,)`` named ``{"axes": null}``, ``action`` float32 ``(4,)`` named
``{"axes": ["x", "y", "z", "gripper"]}``, ``next.reward`` float32 and ``next.success`` bool ``(1,)``,
``observation.environment_state`` float32 ``(39,)`` (MetaWorld's full observation) and ``task_id`` int16, at
``fps`` 80, ``robot_type`` ``metaworld``. A recording here has the image (as video, at ``benchmark.image_size``),
state, action, reward and success features with those names, dtypes and shapes, that fps and robot type (and, as
theirs, no ``next.done``); it has no ``observation.environment_state`` and no ``task_id`` column (the task is the
frame's ``task``, its id in ``meta/eval/episodes.jsonl``), so it does not merge with ``lerobot/metaworld_mt50`` as
it is.
"""

from __future__ import annotations

from molmo_lerobot.dataset_layout import DatasetLayout, Vector
from molmo_lerobot.suites.metaworld import ACTION_DIM, CAMERA, CONTROL_HZ, MOVE_GROUP, STATE_DIM

ROBOT_TYPE = "metaworld"


def metaworld_layout(image_size: int) -> DatasetLayout:
    """The frame schema of a MetaWorld recording at ``image_size``²."""
    return DatasetLayout(
        image_size=image_size,
        cameras=((CAMERA, "observation.image", "the corner2 camera, moved and flipped on both axes as LeRobot does"),),
        move_group=MOVE_GROUP,
        state=Vector("observation.state", STATE_DIM, {"axes": None},
                     "the Sawyer's hand position (3) and gripper opening (1): MetaWorld's observation[:4]"),
        action=Vector("action", ACTION_DIM, {"axes": ["x", "y", "z", "gripper"]},
                      "the hand's position delta (3, scaled by MetaWorld's 1/100) and gripper effort, each in [-1, 1]"),
        robot_type=ROBOT_TYPE, fps=CONTROL_HZ, step_hz=CONTROL_HZ, outcomes=("next.reward", "next.success"),
        simulator="MetaWorld 3.0's Sawyer tasks, simulated in MuJoCo; the images are MuJoCo renders")
