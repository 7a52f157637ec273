"""``sim.geometry.subtree``: a body and everything below it, in one pass over the bodies."""

from __future__ import annotations

import mujoco

from molmo_lerobot.sim.geometry import subtree


def test_subtree_holds_the_body_and_its_descendants_only():
    spec = mujoco.MjSpec()
    a = spec.worldbody.add_body(name="a")
    b = a.add_body(name="b")
    b.add_body(name="b1")
    a.add_body(name="a2")
    spec.worldbody.add_body(name="c").add_body(name="c1")
    m = spec.compile()
    ids = {m.body(i).name: i for i in range(m.nbody)}
    assert subtree(m, ids["a"]) == {ids[n] for n in ("a", "b", "b1", "a2")}
    assert subtree(m, ids["b"]) == {ids["b"], ids["b1"]}
    assert subtree(m, ids["c1"]) == {ids["c1"]}
    assert subtree(m, 0) == set(range(m.nbody))
