"""The preflight looks added objects up MolmoSpaces' way (under the assets dir, else by UID) only in
MolmoSpaces scene datasets; another dataset attaches them as the episode gives them (``SceneDataset.modify``)."""

from __future__ import annotations

import pytest

from molmo_lerobot.benchmark.task_specs import parse_episode
from molmo_lerobot.content.tabletop.generate import generate_benchmark
from molmo_lerobot.context import RunContext
from molmo_lerobot.molmospaces import preflight, scenes


def test_added_objects_of_a_non_molmospaces_scene_are_not_resolved_as_molmospaces_files(monkeypatch):
    def resolve(rel, field, ctx):
        pytest.fail(f"{field} resolved MolmoSpaces' way in a {spec.scene_dataset} episode")

    monkeypatch.setattr(scenes, "resolve_object_file", resolve)
    run = RunContext.build()
    raw = generate_benchmark("pick", 1, 1, 3, "test")[0][0]
    raw["scene_modifications"]["added_objects"] = {"extra": "objects/extra.xml"}
    spec = parse_episode(raw, run.plugins)
    assert preflight._missing(spec, run, None) is None
