"""The dataset store's namespaces and datasets (``molmo_lerobot.namespaces``), locally and on the Hub stand-in."""

from __future__ import annotations

import json
import warnings

import pytest

from molmo_lerobot import namespaces as ns
from molmo_lerobot.namespaces import DatasetStore, NamespaceError


@pytest.fixture
def home(tmp_path, monkeypatch):
    monkeypatch.delenv("MOLMO_DATASETS_PATH", raising=False)
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "home"))
    return tmp_path / "home" / "datasets"


def _fake_dataset(path, frames=b"frames"):
    """A directory LeRobot would take for a dataset (``meta/info.json``) with one data file."""
    (path / "meta").mkdir(parents=True)
    (path / "meta" / "info.json").write_text('{"codebase_version": "v3.0"}')
    (path / "data").mkdir()
    (path / "data" / "file-000.parquet").write_bytes(frames)
    return path


def _files(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_namespaces_nest_list_update_and_delete_with_minaris_files(home):
    ns.create_namespace("molmo/evals/pick", description="pick runs", owner="me")
    assert home.is_dir()
    assert ns.list_local_namespaces() == ["molmo", "molmo/evals", "molmo/evals/pick"]
    assert _files(home) == {"molmo/namespace_metadata.json": b"{}", "molmo/evals/namespace_metadata.json": b"{}",
                            "molmo/evals/pick/namespace_metadata.json":
                                b'{"owner": "me", "description": "pick runs"}'}
    ns.update_namespace_metadata("molmo/evals", tag=1)
    assert ns.get_namespace_metadata("molmo/evals") == {"tag": 1, "description": None}
    assert list(ns.namespace_hierarchy("a/b/c")) == ["a", "a/b", "a/b/c"]
    ns.delete_namespace("molmo/evals/pick")
    assert ns.list_local_namespaces() == ["molmo", "molmo/evals"]
    with pytest.warns(UserWarning, match="does not exist"):
        ns.delete_namespace("molmo/evals/pick")


@pytest.mark.parametrize("call", [
    lambda: ns.create_namespace("a"), lambda: ns.create_namespace("a//b"), lambda: ns.get_namespace_metadata("x y"),
    lambda: ns.update_namespace_metadata("nope/nope"), lambda: ns.get_namespace_metadata("nope"),
    lambda: ns.create_namespace("molmo"), lambda: ns.delete_namespace("molmo"),
])
def test_every_error_is_one_line_naming_the_id_and_loses_nothing(home, call):
    ns.create_namespace("molmo/evals", description="kept")
    before = _files(home)
    with pytest.raises(NamespaceError) as err:
        call()
    text = str(err.value)
    assert "\n" not in text and "'" in text  # the id, quoted
    assert _files(home) == before


def test_deleting_a_non_empty_namespace_names_what_it_holds(home):
    store = DatasetStore()
    store.create_namespace("molmo/evals")
    _fake_dataset(home / "molmo" / "evals" / "run-a")
    with pytest.raises(NamespaceError, match=r"^namespace 'molmo/evals' is not empty \(it holds run-a\)"):
        store.delete_namespace("molmo/evals")
    assert (home / "molmo" / "evals" / "run-a" / "data" / "file-000.parquet").read_bytes() == b"frames"


def test_datasets_are_copied_in_listed_and_never_overwritten(home, tmp_path):
    store = DatasetStore()
    src = _fake_dataset(tmp_path / "run1" / "dataset")
    store.add_dataset("molmo/evals/pick/a", src, {"policy": "scripted"}, run_dir=tmp_path / "run1")
    # parents are created as Minari creates them (empty metadata); the listing never enters a dataset
    assert store.list_local_namespaces() == ["molmo", "molmo/evals", "molmo/evals/pick"]
    assert list(store.list_local_datasets()) == ["molmo/evals/pick/a"]
    assert store.dataset_metadata("molmo/evals/pick/a") == {"dataset_id": "molmo/evals/pick/a", "policy": "scripted"}
    assert store.run_dir("molmo/evals/pick/a") == (tmp_path / "run1").resolve()
    assert _files(src) == {k: v for k, v in _files(home / "molmo/evals/pick/a").items()
                           if not k.startswith((".", "meta/eval/"))}
    before = _files(home)
    other = _fake_dataset(tmp_path / "run2" / "dataset", b"other")
    for ident, msg in [("molmo/evals/pick/a", "collides with an existing dataset"),
                       ("molmo/evals/pick", "collides with the namespace"),
                       ("molmo/evals/pick/a/inner", "lies inside the dataset 'molmo/evals/pick/a'")]:
        with pytest.raises(NamespaceError, match=msg) as err:
            store.add_dataset(ident, other, {}, run_dir=tmp_path / "run2")
        assert "\n" not in str(err.value) and repr(ident) in str(err.value)
    with pytest.raises(NamespaceError, match="collides with the dataset"):
        store.create_namespace("molmo/evals/pick/a")
    assert _files(home) == before and not [p for p in home.iterdir() if p.name.startswith(ns.STAGING_PREFIX)]
    # the same run (a resume) replaces its own recording
    store.add_dataset("molmo/evals/pick/a", other, {"policy": "scripted"}, run_dir=tmp_path / "run2" / ".." / "run1")
    assert (home / "molmo/evals/pick/a/data/file-000.parquet").read_bytes() == b"other"


def test_hub_namespaces_and_datasets_round_trip(home, tmp_path, hub_standin, monkeypatch):
    from huggingface_hub import HfApi

    monkeypatch.setenv("MOLMO_DATASETS_REMOTE", "hf://molmo-test")
    store = DatasetStore()
    store.create_namespace("molmo/evals", description="eval runs")
    store.add_dataset("molmo/evals/run-a", _fake_dataset(tmp_path / "r" / "dataset"), {"policy": "scripted"})
    ns.upload_dataset("molmo/evals/run-a")
    # Minari's mapping: the top namespace is the repo, the rest folders in it, registered in its root metadata
    files = {f.rfilename for f in HfApi().dataset_info("molmo-test/molmo").siblings}
    assert files == {"namespace_metadata.json", "evals/namespace_metadata.json", "evals/run-a/meta/info.json",
                     "evals/run-a/data/file-000.parquet", "evals/run-a/meta/eval/dataset_metadata.json"}
    assert sorted(ns.list_remote_namespaces()) == ["molmo", "molmo/evals"]
    assert ns.list_remote_datasets() == ["molmo/evals/run-a"]
    with pytest.warns(UserWarning, match="already on the Hub"):
        ns.upload_namespace("molmo/evals")
    # uploaded again (a resumed run's new recording): the files it no longer has go
    (store.path("molmo/evals/run-a") / "data" / "file-000.parquet").unlink()
    (store.path("molmo/evals/run-a") / "data" / "file-001.parquet").write_bytes(b"new")
    ns.upload_dataset("molmo/evals/run-a")
    files = {f.rfilename for f in HfApi().dataset_info("molmo-test/molmo").siblings}
    assert "evals/run-a/data/file-001.parquet" in files and "evals/run-a/data/file-000.parquet" not in files
    assert "evals/namespace_metadata.json" in files
    # a clean home: one namespace's metadata (only that one, as Minari)
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "clean"))
    ns.download_namespace_metadata("molmo/evals")
    assert ns.get_namespace_metadata("molmo/evals") == {"description": "eval runs"}
    assert ns.list_local_namespaces() == ["molmo/evals"]
    # another: the dataset brings the metadata of its namespaces missing here
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "clean2"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ns.download_dataset("molmo/evals/run-a")
    clean = DatasetStore()
    assert clean.list_local_namespaces() == ["molmo", "molmo/evals"]
    assert json.loads((clean.root / "molmo" / "namespace_metadata.json").read_text()) == {
        "namespaces": ["molmo/evals"], "datasets": ["molmo/evals/run-a"]}
    assert _files(clean.path("molmo/evals/run-a")) == {k: v for k, v in _files(store.path("molmo/evals/run-a")).items()
                                                       if not k.startswith(".")}
    assert not [p for p in clean.root.iterdir() if p.name.startswith(".")]
    with pytest.raises(NamespaceError, match="'molmo/nope' is not on the Hub"):
        ns.download_namespace_metadata("molmo/nope")


def test_molmo_datasets_cli(tmp_path, capsys, monkeypatch):
    from molmo_lerobot.cli.datasets import main

    monkeypatch.delenv("MOLMO_DATASETS_REMOTE", raising=False)
    monkeypatch.delenv("MOLMO_DATASETS_PATH", raising=False)

    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0 and "molmo-datasets" in capsys.readouterr().out  # argparse, no Hydra
    root = ["--root", str(tmp_path / "store")]
    assert main([*root, "create", "molmo/evals", "--description", "eval runs", "--set", "n=3"]) == 0
    assert main([*root, "show", "molmo/evals"]) == 0
    assert json.loads(capsys.readouterr().out) == {"n": 3, "description": "eval runs"}
    _fake_dataset(tmp_path / "store" / "molmo" / "evals" / "run-a")
    assert main([*root, "list"]) == 0
    assert capsys.readouterr().out.splitlines()[1:] == ["namespace  molmo", "namespace  molmo/evals",
                                                        "dataset    molmo/evals/run-a"]
    assert main([*root, "delete", "molmo/evals"]) == 2
    assert capsys.readouterr().err == ("molmo-datasets: error: namespace 'molmo/evals' is not empty (it holds "
                                       "run-a); delete its datasets and namespaces first\n")
    assert main([*root, "delete-dataset", "molmo/evals/run-a"]) == 0
    assert main([*root, "delete", "molmo/evals"]) == 0
    assert main([*root, "delete", "molmo/evals"]) == 0
    assert capsys.readouterr().err == "molmo-datasets: warning: namespace 'molmo/evals' does not exist in " \
                                      f"{tmp_path / 'store'}\n"
    assert main([*root, "update", "x"]) == 2
    assert main([*root, "push", "molmo"]) == 2  # no remote configured
    assert "no remote" in capsys.readouterr().err
