"""Asset and grasp libraries are plugin kinds: a run's catalog holds every type the plugins provide,
in priority order; a type name two plugins provide is a clash like any other kind's."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from molmo_lerobot.assets import AssetError
from molmo_lerobot.assets.grasps import save_grasp_file
from molmo_lerobot.context import RunContext
from molmo_lerobot.molmospaces.libraries import MolmoSpacesObjects
from molmo_lerobot.plugins import ENTRY_POINT_GROUP, PluginConflict

TOY = textwrap.dedent("""
    from molmo_lerobot import hookimpl
    from molmo_lerobot.assets import AssetLibraryType, GraspLibrary, GraspLibraryType
    from molmo_lerobot.assets.libraries import ObjectTableLibrary


    class Vase:
        def metadata(self):
            return {"assetId": "toy_vase", "category": "vase"}

        def mjcf(self):
            return "<mujoco model='toy_vase'><worldbody><body/></worldbody></mujoco>"


    def _vases(settings, catalog):
        return [ObjectTableLibrary("toy", {"toy_vase": Vase()}, GraspLibrary(settings.assets / "shipped"))]


    def _extra(settings, catalog):
        return [(GraspLibrary(settings.assets / "extra", name="toy_extra"), "toy")]


    @hookimpl
    def molmo_asset_libraries():
        return [AssetLibraryType("toy", _vases, priority=250)]


    @hookimpl
    def molmo_grasp_libraries():
        return [GraspLibraryType("toy_extra", _extra, priority=250)]
""")

IMPOSTOR = textwrap.dedent("""
    from molmo_lerobot import hookimpl
    from molmo_lerobot.assets import AssetLibraryType


    @hookimpl
    def molmo_asset_libraries():
        return [AssetLibraryType("thor", lambda settings, catalog: [], priority=100)]
""")


@pytest.fixture
def toy_dist(tmp_path: Path, monkeypatch) -> Path:
    """A distribution ``toylibs`` (on ``sys.path``) with a library plugin ``toy`` and one ``impostor``
    that provides a second ``thor``."""
    site = tmp_path / "site"
    info = site / "toylibs-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toylibs\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\ntoy = toylibs_toy\nimpostor = toylibs_impostor\n")
    (site / "toylibs_toy.py").write_text(TOY)
    (site / "toylibs_impostor.py").write_text(IMPOSTOR)
    monkeypatch.syspath_prepend(str(site))
    return tmp_path


def _pose(z: float) -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = z
    return np.stack([T])


def test_a_library_plugin_joins_every_run_catalog_by_priority(toy_dist):
    assets = toy_dist / "assets"
    save_grasp_file(assets / "shipped" / "franka" / "toy_vase.npz", _pose(0.1))
    save_grasp_file(assets / "extra" / "franka" / "toy_vase.npz", _pose(0.2))
    pin = {"asset_library": {"thor": "molmospaces"}}
    run = RunContext.build({"molmospaces": {"assets_dir": str(assets)}, "plugins": {"prefer": pin}})
    record = next(r for r in run.plugins.records if r.name == "toy")
    assert record.kinds == ["asset_library", "grasp_library"]
    assert record.provides == ["asset_library:toy", "grasp_library:toy_extra"]
    cat = run.catalog
    assert [lib.name for lib in cat.libraries] == ["builtin", "toy", "articulated", "libero", "libero_fixtures", "thor",
                                                   "objaverse"]
    assert [(g.name, owner) for g, owner in cat.grasp_libraries] == [
        ("builtin", "builtin"), ("toy_extra", "toy"), ("shipped", "toy"), ("articulated", "articulated"),
        ("libero", "libero"), ("libero_fixtures", "libero_fixtures"), ("droid", "thor"),
        ("droid_objaverse", "objaverse")]
    assert cat.annotation("toy_vase")["category"] == "vase" and cat.locate_uid("toy_vase").library == "toy"
    assert cat.get_grasps("toy_vase")[0, 2, 3] == 0.2  # a grasp type goes ahead of the grasps a library ships
    assert isinstance(cat.library("thor"), MolmoSpacesObjects)


def test_a_library_type_two_plugins_provide_fails_the_run_unless_pinned(toy_dist):
    with pytest.raises(PluginConflict, match=r"asset_library 'thor' is provided by plugin 'impostor'.* and plugin "
                                             r"'molmospaces'.*plugins\.prefer\.asset_library\.thor=<plugin>"):
        RunContext.build()
    run = RunContext.build({"plugins": {"prefer": {"asset_library": {"thor": "impostor"}}}})
    assert "thor" not in [lib.name for lib in run.catalog.libraries]  # the impostor's thor makes no library


def test_a_user_library_taking_a_library_name_fails_naming_the_key(tmp_path):
    lib = tmp_path / "lib"
    lib.mkdir()
    (lib / "assets_index.json").write_text(json.dumps({}))
    with pytest.raises(AssetError, match=r"^asset_libraries.builtin: an asset library named 'builtin' is already"):
        RunContext.build({"asset_libraries": {"builtin": str(lib)}})
    with pytest.raises(AssetError, match=r"^grasp_libraries.g: .*no asset library named 'nope'"):
        RunContext.build({"grasp_libraries": {"g": {"path": str(lib), "asset_library": "nope"}}})
    run = RunContext.build({"asset_libraries": {"a": str(lib), "b": str(lib)}})
    assert [lib.name for lib in run.catalog.libraries][:3] == ["b", "a", "builtin"]  # the last configured goes first
