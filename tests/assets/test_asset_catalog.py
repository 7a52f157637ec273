"""Asset and grasp libraries: built-ins, user libraries registered at runtime, packed libraries."""

from __future__ import annotations

import json

import numpy as np
import pytest

from molmo_lerobot.assets import (
    AssetCatalog,
    AssetError,
    BuiltinAssetLibrary,
    GraspError,
    ResourceAssetLibrary,
)
from molmo_lerobot.assets.builtin import BUILTIN_OBJECTS, analytic_grasps
from molmo_lerobot.assets.grasps import (
    count_grasp_file,
    generate_builtin_grasps,
    save_grasp_file,
)
from molmo_lerobot.molmospaces.user import (
    register_user_asset_library,
    register_user_grasp_library,
)
from molmo_lerobot.resources import ResourceManager, pack

UID = "builtin_red_can"


def _pose(z: float) -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = z
    return T


@pytest.fixture
def user_lib(tmp_path):
    """A MolmoSpaces-format user library: a new object, an override of a built-in's metadata, grasps,
    per-joint grasps (``assets_index.json`` + ``grasps_index.json`` in one directory)."""
    root = tmp_path / "userlib"
    for d in ("my_cabinet/franka", f"{UID}/franka"):
        (root / d).mkdir(parents=True)
    (root / "my_cabinet" / "my_cabinet.xml").write_text("<mujoco model='cabinet'/>")
    (root / UID / "can.xml").write_text("<mujoco model='user can'/>")
    (root / "my_cabinet" / "my_cabinet.json").write_text(json.dumps(
        {"assetId": "my_cabinet", "category": "cabinet", "description": "oak cabinet", "mass": 12.0}))
    (root / UID / f"{UID}.json").write_text(json.dumps({"assetId": UID, "description": "user red can"}))
    np.savez(root / "my_cabinet" / "my_cabinet.npz", handle_positions=np.ones((2, 3)))
    (root / "assets_index.json").write_text(json.dumps({
        "my_cabinet": {"uid": "my_cabinet", "object_path": "my_cabinet/my_cabinet.xml",
                       "metadata_path": "my_cabinet/my_cabinet.json", "metadata_npz_path": "my_cabinet/my_cabinet.npz"},
        UID: {"uid": UID, "object_path": f"{UID}/can.xml", "metadata_path": f"{UID}/{UID}.json",
              "metadata_npz_path": None}}))
    save_grasp_file(root / UID / "franka" / "grasps.npz", np.stack([_pose(0.5)] * 3))
    save_grasp_file(root / "my_cabinet" / "franka" / "joint_grasps_door_hinge.npz", np.stack([_pose(0.1)] * 4))
    save_grasp_file(root / "my_cabinet" / "franka" / "joint_grasps_drawer_slide.npz", np.stack([_pose(0.2)] * 2))
    (root / "grasps_index.json").write_text(json.dumps({
        "grasp_paths": {"franka": {UID: f"{UID}/franka/grasps.npz"}},
        "articulated_grasp_paths": {"franka": {"my_cabinet": {
            "door_hinge": "my_cabinet/franka/joint_grasps_door_hinge.npz",
            "drawer_slide": "my_cabinet/franka/joint_grasps_drawer_slide.npz"}}}}))
    return root


def _builtin_catalog():
    cat = AssetCatalog()
    cat.register_library(BuiltinAssetLibrary())
    return cat


def _register(cat, root, name="mine"):
    lib = register_user_asset_library(cat, name, root)
    register_user_grasp_library(cat, f"{name}_grasps", root, name)
    return lib


def test_builtin_set_is_an_asset_library():
    cat = _builtin_catalog()
    for uid, obj in BUILTIN_OBJECTS.items():
        assert cat.annotation(uid) == obj.metadata()
        assert cat.locate_uid(uid).library == "builtin"
        assert cat.mjcf(uid) == obj.mjcf()
    doc = cat.annotation(UID)
    assert set(doc) >= {"assetId", "category", "description", "description_long", "description_short",
                        "synset", "mass", "boundingBox"}
    with pytest.raises(AssetError, match="did you mean 'builtin_red_can'"):
        cat.annotation("builtin_red_cann")


def test_builtin_grasps_fall_back_then_use_generated_files(tmp_path, monkeypatch):
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "home"))
    cat = _builtin_catalog()
    fresh = cat.get_grasps(UID)  # no NPZ generated yet: analytic grasps
    np.testing.assert_allclose(fresh, analytic_grasps(BUILTIN_OBJECTS[UID]))
    files = generate_builtin_grasps()
    assert len(files) == len(BUILTIN_OBJECTS) and files[0].parent == tmp_path / "home" / "grasps" / "builtin" / "franka"
    save_grasp_file(files[0].parent / f"{UID}.npz", fresh[:5])  # the generated file is what is read
    cat = _builtin_catalog()
    assert cat.get_grasps(UID).shape == (5, 4, 4) and cat.count_grasps(UID) == 5
    with pytest.raises(GraspError, match="no grasps for 'builtin_red_can' and robot 'ur5'"):
        cat.get_grasps(UID, robot="ur5")


def test_get_grasps_works_on_fresh_clone(tmp_path, monkeypatch):
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "empty"))
    g = _builtin_catalog().get_grasps("builtin_red_block")
    assert g.ndim == 3 and g.shape[1:] == (4, 4) and len(g) > 0


def test_user_library_registered_at_runtime(user_lib, tmp_path, monkeypatch):
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "home"))
    cat = _builtin_catalog()
    lib = _register(cat, user_lib)
    assert lib.name == "mine" and [library.name for library in cat.libraries] == ["mine", "builtin"]
    loc = cat.locate_uid("my_cabinet")
    assert (loc.library, loc.archive, loc.mjcf_path) == ("mine", None, user_lib / "my_cabinet" / "my_cabinet.xml")
    doc = cat.annotation("my_cabinet")
    assert doc["category"] == "cabinet" and doc["handle_positions"].shape == (2, 3)
    # the union: the user library overrides the description, the built-in fills the other fields
    can = cat.annotation(UID)
    assert can["description"] == "user red can" and can["synset"] == "can.n.01" and can["mass"] == 0.15
    assert cat.locate_uid(UID).library == "mine" and cat.mjcf(UID) == "<mujoco model='user can'/>"
    # user grasps come first, for UIDs of every library holding them
    assert cat.get_grasps(UID).shape == (3, 4, 4) and cat.get_grasps(UID)[0, 2, 3] == 0.5
    assert cat.count_grasps(UID) == 3
    # articulated: per-joint grasp files
    assert cat.grasp_joints("my_cabinet") == ["door_hinge", "drawer_slide"]
    assert cat.get_grasps("my_cabinet", joint="drawer_slide").shape == (2, 4, 4)
    assert cat.count_grasps("my_cabinet", joint="door_hinge") == 4
    with pytest.raises(GraspError, match="joint 'lid'"):
        cat.get_grasps("my_cabinet", joint="lid")
    with pytest.raises(AssetError, match="already registered"):
        register_user_asset_library(cat, "mine", user_lib)


def test_newest_grasp_library_goes_first(user_lib, tmp_path):
    cat = _builtin_catalog()
    _register(cat, user_lib)
    extra = tmp_path / "extra_grasps"
    save_grasp_file(extra / "franka" / f"{UID}.npz", np.stack([_pose(0.9)]))
    cat.register_grasp_library(extra)
    assert cat.get_grasps(UID)[0, 2, 3] == 0.9
    scoped = tmp_path / "scoped"
    save_grasp_file(scoped / "franka" / "builtin_orange.npz", np.stack([_pose(0.7)] * 2))
    cat.register_grasp_library(scoped, asset_library="mine")  # only for UIDs of "mine": not the orange
    assert cat.get_grasps("builtin_orange").shape[0] != 2


def test_malformed_user_libraries_name_the_file(tmp_path):
    root = tmp_path / "bad"
    root.mkdir()
    cat = _builtin_catalog()
    with pytest.raises(AssetError, match=r"bad/assets_index.json: file not found"):
        register_user_asset_library(cat, "bad", root)
    (root / "assets_index.json").write_text("{not json")
    with pytest.raises(AssetError, match=r"assets_index.json: invalid JSON"):
        register_user_asset_library(cat, "bad", root)
    (root / "assets_index.json").write_text(json.dumps({"x": {"uid": "x", "object_path": "x.xml"}}))
    with pytest.raises(AssetError, match=r"assets_index.json: field x.object_path: .*x.xml not found"):
        register_user_asset_library(cat, "bad", root)
    (root / "x.xml").write_text("<mujoco/>")
    with pytest.raises(AssetError, match=r"assets_index.json: field x.metadata_path: missing"):
        register_user_asset_library(cat, "bad", root)
    save_bad = tmp_path / "g" / "franka" / "x.npz"
    save_bad.parent.mkdir(parents=True)
    np.savez(save_bad, transforms=np.zeros((3, 3, 3)))
    with pytest.raises(GraspError, match=r"x.npz: 'transforms' must have shape \(N, 4, 4\)"):
        count_grasp_file(save_bad)


def test_count_reads_the_header_only(tmp_path, monkeypatch):
    path = save_grasp_file(tmp_path / "franka" / "big.npz", np.tile(np.eye(4), (10_000, 1, 1)))
    monkeypatch.setattr(np.lib.format, "read_array", lambda *a, **k: pytest.fail("array data was read"))
    monkeypatch.setattr(np, "load", lambda *a, **k: pytest.fail("np.load was called"))
    assert count_grasp_file(path) == 10_000


def test_packed_library_metadata_in_lmdb_and_install_uid(tmp_path, user_lib):
    objects, grasps = tmp_path / "objects_src", tmp_path / "grasps_src"
    docs = []
    for uid in ("vase_01", "lamp_02"):
        (objects / uid).mkdir(parents=True)
        (objects / uid / f"{uid}.xml").write_text(f"<mujoco model='{uid}'/>")
        docs.append({"assetId": uid, "category": uid.split("_")[0], "description": f"a {uid}"})
        save_grasp_file(grasps / "franka" / f"{uid}.npz", np.stack([_pose(0.3)] * 6))
    (objects / "metadata.jsonl").write_text("\n".join(json.dumps(d) for d in docs) + "\n")
    remote = tmp_path / "remote"
    pack(objects, remote, "objects/packed@1", max_archive_bytes=1)  # one archive per UID
    pack(grasps, remote, "grasps/packed@1", uid_depth=1, max_archive_bytes=1)
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", remote, progress=False)
    mgr.install("objects/packed@1", on_demand=True)
    mgr.install("grasps/packed@1", on_demand=True)
    cat = _builtin_catalog()
    cat.register_library(ResourceAssetLibrary(mgr, "objects/packed@1", "grasps/packed@1"))
    _register(cat, user_lib)  # registered later: first in priority
    assert cat.annotation("lamp_02")["category"] == "lamp"
    assert (mgr.meta_dir("objects/packed@1") / "metadata.lmdb" / "data.mdb").is_file()
    loc = cat.locate_uid("vase_01")
    assert loc.library == "packed" and loc.archive.endswith(".tar.zst")
    assert loc.mjcf_path == tmp_path / "install" / "objects" / "packed" / "vase_01" / "vase_01.xml"
    assert not loc.mjcf_path.exists()  # on demand: not fetched yet
    cat.install_uid("vase_01")
    assert loc.mjcf_path.read_text() == "<mujoco model='vase_01'/>"
    assert (tmp_path / "install" / "grasps" / "packed" / "franka" / "vase_01.npz").exists()
    assert not (tmp_path / "install" / "grasps" / "packed" / "franka" / "lamp_02.npz").exists()
    assert cat.get_grasps("lamp_02").shape == (6, 4, 4)  # grasp lookup installs the UID's grasps
    assert cat.count_grasps("vase_01") == 6
    assert sorted(cat.library("packed").uids()) == ["lamp_02", "vase_01"]
