"""MjSpec fields whose type differs between the MuJoCo versions we run: 3.5 (MolmoSpaces' pin)
and 4.x. Code that edits specs sets them through these helpers and runs unchanged on both."""

from __future__ import annotations

import mujoco


def set_joint_damping(joint: mujoco.MjsJoint, damping: float) -> None:
    """Linear joint damping (N·m·s/rad or N·s/m): a float in MuJoCo 3.x, the first term of a
    polynomial in 4.x."""
    if isinstance(joint.damping, float):
        joint.damping = float(damping)
    else:
        joint.damping = [float(damping)] + [0.0] * (len(joint.damping) - 1)


def equality_data(*values: float) -> list[float]:
    """An equality's ``data`` starting with ``values``, zero-padded to this MuJoCo's length (11 in
    3.x, 12 in 4.x)."""
    size = len(mujoco.MjSpec().add_equality().data)
    return [float(v) for v in values] + [0.0] * (size - len(values))
