"""A visibility stand-in both sides answer identically: which camera positions "see" which bodies.

The camera-placement comparisons (tests/parity/test_eval_cameras.py) need the redraw loops of
MolmoSpaces and ours to get the same visible/occluded answer for the same camera pose, whatever
renderer each side has. A camera at ``pos`` sees a body when the azimuth of ``pos`` around
``centre`` passes ``sin(lobes * azimuth + phase) > cut``; the gripper (``gripper`` in the body's
name) also needs the camera at least ``rise`` above the centre. Seen bodies cover 0.5 of the image,
others 0. Standard library and numpy only: it is imported in MolmoSpaces' venv too.
"""

from __future__ import annotations

import math


def fractions(pos, bodies, oracle: dict) -> dict[str, float]:
    cx, cy, cz = oracle["centre"]
    azimuth = math.atan2(float(pos[1]) - cy, float(pos[0]) - cx)
    around = math.sin(oracle["lobes"] * azimuth + oracle["phase"]) > oracle["cut"]
    high = float(pos[2]) - cz >= oracle["rise"]
    return {b: 0.5 if around and (high or "gripper" not in b) else 0.0 for b in bodies}
