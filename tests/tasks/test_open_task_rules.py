"""open with a zero-range joint at 0 listed first: MolmoSpaces' rule (NaN, fails) by default, ours with
``task_rules=fixed``, and ``parity_notes`` naming the episodes where the two differ."""

from __future__ import annotations

import mujoco
import pytest

from molmo_lerobot.sim.geometry import subtree
from molmo_lerobot.tasks.open_close import OpenCloseTask, OpenCloseTaskSpec

# a cabinet whose first joint is an unlimited knob (range 0..0), then a door
CABINET = """
<mujoco><compiler angle="radian"/><worldbody><body name="cabinet"><geom size="0.1 0.1 0.1" type="box"/>
  <body name="knob"><joint name="knob" type="hinge" axis="0 0 1"/><geom size="0.01"/></body>
  <body name="door"><joint name="door" type="hinge" axis="0 0 1" range="0 1.57"/><geom size="0.01"/></body>
</body></worldbody></mujoco>
"""


class CabinetEnv:
    """What the open/close task reads of an Env."""

    def __init__(self, task_rules: str) -> None:
        self.model = mujoco.MjModel.from_xml_string(CABINET)
        self.data = mujoco.MjData(self.model)
        self.task_rules = task_rules
        self.scene_metadata = {"objects": {"cabinet": {"category": "cabinet"}}}

    def body_id(self, name: str, field: str = "body") -> int:
        return self.model.body(name).id

    def subtree_bodies(self, name: str) -> frozenset[int]:
        return subtree(self.model, self.body_id(name))

    def set(self, knob: float, door: float) -> None:
        self.data.qpos[:] = [knob, door]
        mujoco.mj_forward(self.model, self.data)


def task(rules: str) -> tuple[OpenCloseTask, CabinetEnv]:
    env = CabinetEnv(rules)
    spec = OpenCloseTaskSpec.model_construct(pickup_obj_name="cabinet", task_success_threshold=0.2,
                                             joint_name="door", joint_index=1, joint_start_position=0.0)
    return OpenCloseTask(spec, env, "open"), env


@pytest.mark.parametrize(("knob", "door", "theirs", "ours"), [
    (0.0, 1.0, False, True),    # knob at 0 first: their fraction is NaN, the open door does not count
    (0.3, 1.0, True, True),     # a turned knob is skipped (inf) by both
    (0.0, 0.1, False, False),   # not open either way
])
def test_open_judges_by_task_rules(knob, door, theirs, ours):
    for rules, expected in (("molmospaces", theirs), ("fixed", ours)):
        t, env = task(rules)
        env.set(knob, door)
        assert t.success() is expected, rules
        differs = theirs != ours
        notes = t.parity_notes()
        assert len(notes) == differs, rules
        if differs:
            other = "fixed" if rules == "molmospaces" else "molmospaces"
            assert "'knob' at 0" in notes[0] and f"task_rules={other}" in notes[0]


def test_the_default_rules_are_theirs():
    from molmo_lerobot.sim.env import TASK_RULES

    assert TASK_RULES[0] == "molmospaces"
