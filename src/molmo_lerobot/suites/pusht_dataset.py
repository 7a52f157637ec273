"""LeRobot's PushT dataset layout (``lerobot/pusht``): how a PushT episode is recorded with ``record=true``.

``lerobot/pusht`` was written by LeRobot's ``pusht_zarr_format`` (codebase v1.6: ``observation.image`` video,
``observation.state`` the agent's float32 2-D position, ``action`` the float32 2-D target, and per frame the
float32 ``next.reward`` and bool ``next.done`` and ``next.success`` of the state after the frame's action, 10 fps)
and carried to v2.0 by LeRobot's ``convert_dataset_v1_to_v2`` without a robot config, which names each vector's
entries ``{"motors": ["motor_0", ...]}``, gives each per-frame scalar shape ``(1,)`` and no names, and sets
``robot_type`` ``unknown``; v3.0's conversion keeps the features. So a frame here holds exactly:

* ``observation.image``: video ``(96, 96, 3)``, names ``height, width, channel`` (gym_pusht's 96² rendering);
* ``observation.state``, ``action``: float32 ``(2,)``, names ``{"motors": ["motor_0", "motor_1"]}``;
* ``next.reward`` float32 ``(1,)``, ``next.success`` and ``next.done`` bool ``(1,)``: gym_pusht's reward and
  success rule after the action, and whether the episode ended with it;
* ``fps`` 10 (PushT's own control rate: no declared-versus-real difference as for LIBERO), ``robot_type``
  ``unknown``.

The images are the ones the policy saw, at ``benchmark.image_size`` (default 96, their size).
"""

from __future__ import annotations

from molmo_lerobot.dataset_layout import OUTCOMES, DatasetLayout, Vector
from molmo_lerobot.suites.pusht import ACTION_DIM, CAMERA, CONTROL_HZ, MOVE_GROUP

#: ``convert_dataset_v1_to_v2``'s robot type for a dataset converted without a robot config
ROBOT_TYPE = "unknown"
STATE_DIM = 2


def _motors(n: int) -> dict[str, list[str]]:
    return {"motors": [f"motor_{i}" for i in range(n)]}


def pusht_layout(image_size: int) -> DatasetLayout:
    """The frame schema of a PushT recording at ``image_size``²."""
    return DatasetLayout(
        image_size=image_size,
        cameras=((CAMERA, "observation.image", "gym_pusht's top-down rendering of the table"),),
        move_group=MOVE_GROUP,
        state=Vector("observation.state", STATE_DIM, _motors(STATE_DIM),
                     "the agent's 2-D position in the 512 × 512 workspace"),
        action=Vector("action", ACTION_DIM, _motors(ACTION_DIM),
                      "the agent's 2-D target position in that workspace"),
        robot_type=ROBOT_TYPE, fps=CONTROL_HZ, step_hz=CONTROL_HZ, outcomes=tuple(OUTCOMES),
        simulator="gym_pusht's 2-D table, simulated with the pymunk physics engine and drawn with pygame")
