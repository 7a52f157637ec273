"""The published v2 and v3 trials never change: same episodes (content hash), resolved horizons and
thresholds, and the look (render profile) their metadata names, knob for knob.

v3 is v2's episodes through render profile v3 (issue 36): a change to a profile's knobs, to which profile a
benchmark names, or to what a benchmark naming none runs, fails here."""

from __future__ import annotations

import pytest
from test_v1_pinned import assert_trials

from molmo_lerobot.paths import data_path
from molmo_lerobot.sim.render_profile import resolve_profile

PLACE = {"max_place_receptacle_pos_displacement": 0.15, "max_place_receptacle_rot_displacement": 1.0472,
         "receptacle_supported_weight_frac": 0.5}
#: task -> (content sha256, {(horizon steps at 66 ms, source): episodes}, {task type: thresholds})
PINNED = {
    "pick": ("92b578b9ed56eb3cb58d8bf227e7203e2989bae07f9b06822f5a80609f0f08e2", {(303, "task_horizon_sec"): 100},
             {"pick": {"succ_pos_threshold": 0.01}}),
    "pick_and_place": ("36d37b4395de63b0cd09e6aef31b6ffd5cd5d6d6a14ed4d5ff57b92555ee08ad",
                       {(606, "task_horizon_sec"): 100}, {"pick_and_place": PLACE}),
    "next_to": ("7ee8a94bfd56a4d5db9a4f59df004b4497c254bfc18c7332dd736f7bf799b511", {(606, "task_horizon_sec"): 100},
                {"pick_and_place_next_to": {**PLACE, "max_surface_to_surface_gap": 0.05,
                                            "min_surface_to_surface_gap": 0.0, "surface_gap_tolerance": 0.01}}),
    "color": ("12e6fbedb38ae09d259af603c54ab5124ae8232670df58acba1fc9528fbadcb8", {(606, "task_horizon_sec"): 100},
              {"pick_and_place_color": PLACE}),
    "open": ("21d19b3a7d539658547781b56b0b74eabaa3768c4c9453a1d68da1c80f429de4", {(227, "task_horizon_sec"): 100},
             {"open": {"task_success_threshold": 0.2}}),
    "close": ("c117b5aa198da6c1fec94add45c9975be3e21c91ffb286846e094ff6c869d7f5", {(227, "task_horizon_sec"): 100},
              {"close": {"task_success_threshold": 0.2}}),
}
#: version -> the render profile its benchmarks run (with no environment override)
LOOK = {
    "v2": {"name": "v2", "shadows": None, "shadow_size": None, "reflections": None, "multisample": None,
           "texture_size": 512, "exposure": 1.0, "overrides": {}},
    "v3": {"name": "v3", "shadows": False, "shadow_size": None, "reflections": False, "multisample": 0,
           "texture_size": 512, "exposure": 0.9, "overrides": {}},
}


def test_every_shipped_v2_and_v3_benchmark_is_pinned():
    shipped = sorted(p.name for p in data_path("benchmarks").iterdir() if p.name.endswith(("_v2", "_v3")))
    assert shipped == sorted(f"{task}_{v}" for task in PINNED for v in LOOK)


@pytest.mark.parametrize("version", sorted(LOOK))
@pytest.mark.parametrize("task", sorted(PINNED))
def test_v2_and_v3_trials_are_unchanged(task, version):
    bench = assert_trials(f"{task}_{version}", *PINNED[task])
    assert resolve_profile(bench.metadata.render_profile, {}).record() == LOOK[version]
