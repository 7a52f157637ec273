"""The Hugging Face remote, and the Hub stand-in it runs against (real ``huggingface_hub`` client)."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest
from huggingface_hub import HfApi, hf_hub_download, snapshot_download
from huggingface_hub.errors import EntryNotFoundError, RepositoryNotFoundError, RevisionNotFoundError

from molmo_lerobot.cli.resources import main
from molmo_lerobot.resources import HfRemote, ResourceManager, open_remote, pack


def test_standin_speaks_the_hub_api(hub_standin, src_tree, tmp_path, read_tree):
    api = HfApi()
    url = api.create_repo("me/data", repo_type="dataset")
    assert str(url) == f"{hub_standin.endpoint}/datasets/me/data"
    api.create_repo("me/data", repo_type="dataset", exist_ok=True)
    first = api.upload_folder(repo_id="me/data", folder_path=src_tree, repo_type="dataset")
    assert sorted(api.list_repo_files("me/data", repo_type="dataset")) == sorted(read_tree(src_tree))
    api.create_branch("me/data", branch="v1", repo_type="dataset")
    api.create_tag("me/data", tag="v3.0", revision="v1", repo_type="dataset")
    api.upload_file(path_or_fileobj=b"new", path_in_repo="README.txt", repo_id="me/data", repo_type="dataset")
    refs = api.list_repo_refs("me/data", repo_type="dataset")
    assert {b.name for b in refs.branches} == {"main", "v1"} and [t.name for t in refs.tags] == ["v3.0"]
    assert api.dataset_info("me/data", revision="v3.0").sha == first.oid != api.dataset_info("me/data").sha
    # snapshot of the tag sees the old README, the branch head the new one
    old = snapshot_download("me/data", repo_type="dataset", revision="v3.0", local_dir=tmp_path / "old")
    assert (tmp_path / "old" / "README.txt").read_text() == "top level\n" and old == str(tmp_path / "old")
    path = hf_hub_download("me/data", "README.txt", repo_type="dataset")
    assert Path(path).read_text() == "new"
    tree = list(api.list_repo_tree("me/data", repo_type="dataset", path_in_repo="mug_02"))
    assert {e.path for e in tree} == {"mug_02/mug_02.xml", "mug_02/same.xml", "mug_02/parts"}
    api.delete_tag("me/data", tag="v3.0", repo_type="dataset")
    with pytest.raises(RevisionNotFoundError):
        api.delete_tag("me/data", tag="v3.0", repo_type="dataset")
    with pytest.raises(RepositoryNotFoundError):
        api.dataset_info("me/absent")
    with pytest.raises(EntryNotFoundError):
        hf_hub_download("me/data", "absent.txt", repo_type="dataset", local_dir=tmp_path / "x")
    r = httpx.get(f"{hub_standin.endpoint}/datasets/me/data/resolve/main/apple_01/mesh.bin",
                  headers={"Range": "bytes=10-19"})
    assert r.status_code == 206 and r.content == (src_tree / "apple_01" / "mesh.bin").read_bytes()[10:20]
    api.create_repo("me/model")  # model repos too
    api.upload_file(path_or_fileobj=b"w", path_in_repo="weights.bin", repo_id="me/model")
    assert api.list_repo_files("me/model") == ["weights.bin"]


def test_hf_remote_round_trip(hub_standin, src_tree, tmp_path, read_tree):
    remote = open_remote("hf://datasets/me/resources/packs")
    assert isinstance(remote, HfRemote) and remote.repo_id == "me/resources" and remote.prefix == "packs"
    pack(src_tree, remote, "objects/lib@1", link="file", max_archive_bytes=2500)
    files = HfApi().list_repo_files("me/resources", repo_type="dataset")
    assert "packs/objects/lib/1/manifest.json" in files and all(f.startswith("packs/") for f in files)
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", remote, progress=False)
    res = mgr.install("objects/lib@1")
    assert res.extracted == 3
    assert read_tree(res.path) == read_tree(src_tree)
    assert mgr.verify() == []
    with pytest.raises(Exception, match="already exists"):
        pack(src_tree, remote, "objects/lib@1")


def test_cli_with_hf_remote(hub_standin, src_tree, tmp_path, capsys, read_tree):
    url = "hf://datasets/me/cli"
    assert main(["pack", str(src_tree), "--remote", url, "--data-type", "scenes", "--source", "s",
                 "--version", "2"]) == 0
    assert main(["install", "scenes/s@2", "--remote", url, "--cache-dir", str(tmp_path / "c"), "--install-dir",
                 str(tmp_path / "i"), "--on-demand", "--no-progress"]) == 0
    assert "0 archives extracted" in capsys.readouterr().out
    mgr = ResourceManager(tmp_path / "c", tmp_path / "i", url, progress=False)
    assert mgr.ensure_path("scenes/s@2", "mug_02/mug_02.xml").read_text() == "<mujoco model='mug'/>\n"
    assert main(["list", "--cache-dir", str(tmp_path / "c"), "--remote", url]) == 0
    assert "remote scenes/s: 2" in capsys.readouterr().out
