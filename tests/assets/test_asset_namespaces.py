"""Dataset namespaces with Minari's semantics, locally and on remotes."""

from __future__ import annotations

import pytest

from molmo_lerobot.assets import namespaces as ns
from molmo_lerobot.assets.namespaces import NamespaceError


@pytest.mark.parametrize("good", ["ab", "molmo/pick", "org-1/sub_2/deeper", "a_b"])
def test_valid_namespaces(good):
    assert ns.validate_namespace_id(good) == good


@pytest.mark.parametrize("bad", ["", "a", "/abs", "trailing/", "dou//ble", "sp ace", "dot.ted", "../up", None])
def test_invalid_namespaces(bad):
    with pytest.raises(NamespaceError, match="invalid namespace"):
        ns.validate_namespace_id(bad)


def test_parse_dataset_ids():
    assert ns.parse_dataset_id("molmo/pick/run-v1") == ("molmo/pick", "run-v1")
    assert ns.parse_dataset_id("solo") == (None, "solo")
    for bad in ("ns/", "/x", "ns/..", "n s/x"):
        with pytest.raises(NamespaceError):
            ns.parse_dataset_id(bad)


def test_nested_create_list_update_delete(tmp_path):
    root = tmp_path / "datasets"
    ns.create_namespace("org/team/project", {"description": "pick runs"}, root=root)
    assert ns.list_local_namespaces(root) == ["org", "org/team", "org/team/project"]
    assert ns.get_namespace_metadata("org/team/project", root) == {"description": "pick runs"}
    assert ns.get_namespace_metadata("org", root) == {}
    with pytest.raises(NamespaceError, match="already exists"):
        ns.create_namespace("org/team/project", root=root)
    assert ns.update_namespace("org/team/project", {"display_name": "P"}, root) == {
        "description": "pick runs", "display_name": "P"}
    assert ns.update_namespace("org/team/project", {"x": 1}, root, replace=True) == {"x": 1}
    ds = ns.dataset_dir("org/team/project/run-1", root)
    (ds / "meta").mkdir(parents=True)
    assert ns.list_local_datasets(root=root) == ["org/team/project/run-1"]
    assert ns.list_local_datasets("org/team", root) == ["org/team/project/run-1"]
    with pytest.raises(NamespaceError, match="not empty .*run-1"):
        ns.delete_namespace("org/team/project", root)
    with pytest.raises(NamespaceError, match="not empty .*project"):
        ns.delete_namespace("org/team", root)
    with pytest.raises(NamespaceError, match="does not exist"):
        ns.delete_namespace("org/other", root)
    (ds / "meta").rmdir()
    ds.rmdir()
    ns.delete_namespace("org/team/project", root)
    assert ns.list_local_namespaces(root) == ["org", "org/team"]
    with pytest.raises(NamespaceError, match="must be a JSON object"):
        ns.create_namespace("bad", ["not", "a", "dict"], root=root)
    (ns.dataset_dir("org/team/run-2", root) / "meta").mkdir(parents=True)
    with pytest.raises(NamespaceError, match="is not a namespace"):
        ns.create_namespace("org/team/run-2", root=root)


def test_dataset_dir_creates_namespaces_on_request(tmp_path, monkeypatch):
    monkeypatch.setenv("MOLMO_LEROBOT_DATASETS", str(tmp_path / "env_root"))
    path = ns.dataset_dir("bench/pick_v1/scripted-eval", create_namespaces=True)
    assert path == tmp_path / "env_root" / "bench" / "pick_v1" / "scripted-eval"
    assert ns.namespace_exists("bench/pick_v1")


def test_remote_listing_local_and_hub(tmp_path, hub_standin):
    root = tmp_path / "datasets"
    ns.create_namespace("org/team", {"description": "shared"}, root=root)
    for remote in (tmp_path / "remote", "hf://datasets/me/namespaces"):
        ns.upload_namespace("org", remote, root)
        ns.upload_namespace("org/team", remote, root)
        assert ns.list_remote_namespaces(remote) == ["org", "org/team"]
        assert ns.get_remote_namespace_metadata(remote, "org/team") == {"description": "shared"}
        with pytest.raises(NamespaceError, match="not found"):
            ns.get_remote_namespace_metadata(remote, "nope/x")
