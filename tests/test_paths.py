"""Assets inside installed registry packages are found, and a missing one is named clearly."""

import pytest

from molmo_lerobot.paths import package_asset_dir


def test_installed_package_assets_are_found():
    path = package_asset_dir("gymnasium_robotics", "envs", "assets", "kitchen_franka", "franka_assets",
                             marker="chain.xml", what="the Franka robot")
    assert (path / "chain.xml").is_file()


def test_missing_package_or_assets_are_named():
    with pytest.raises(FileNotFoundError, match=r"the thing: the 'no-such-pkg' package is not installed"):
        package_asset_dir("no_such_pkg", "x", marker="m", what="the thing")
    with pytest.raises(FileNotFoundError, match=r"the thing: assets not found at .*nowhere"):
        package_asset_dir("gymnasium_robotics", "nowhere", marker="m", what="the thing")
