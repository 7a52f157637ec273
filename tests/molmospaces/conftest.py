"""Fixtures: the stand-in MolmoSpaces assets dir (built once) and the environment pointing at it."""

from __future__ import annotations

import pytest
from standin import build_assets


@pytest.fixture(scope="session")
def standin(tmp_path_factory):
    root = tmp_path_factory.mktemp("mlspaces") / "assets"
    houses = build_assets(root)
    return root, houses


@pytest.fixture
def assets(standin, monkeypatch, tmp_path):
    """The stand-in assets dir as ``MLSPACES_ASSETS_DIR`` (run contexts built from here on read it)."""
    monkeypatch.chdir(tmp_path)  # MuJoCo writes MUJOCO_LOG.TXT (attach warnings) into the working directory
    monkeypatch.setenv("MLSPACES_ASSETS_DIR", str(standin[0]))
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "home"))
    return standin
