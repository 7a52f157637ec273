"""The dataset store against bad input and a hostile remote: ids the filesystem cannot hold, links and
FIFOs planted in the store, pulled files that would decide something local, malformed metadata, and
staging folders left by killed processes. Each refusal is one line and loses nothing."""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from molmo_lerobot import namespaces as ns
from molmo_lerobot.cli.datasets import main as datasets_main
from molmo_lerobot.config import compose
from molmo_lerobot.export.recorder import LeRobotRecorderFactory, RecordConfigError
from molmo_lerobot.namespaces import DatasetStore, NamespaceError
from molmo_lerobot.run_config import RunConfig, RunConfigError

LONG = "x" * 300


@pytest.fixture
def home(tmp_path, monkeypatch):
    monkeypatch.delenv("MOLMO_DATASETS_PATH", raising=False)
    monkeypatch.delenv("MOLMO_DATASETS_REMOTE", raising=False)
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "home"))
    return tmp_path / "home" / "datasets"


def _fake_dataset(path: Path, frames: bytes = b"frames") -> Path:
    (path / "meta").mkdir(parents=True)
    (path / "meta" / "info.json").write_text('{"codebase_version": "v3.0", "total_episodes": 2, "fps": 10}')
    (path / "data").mkdir()
    (path / "data" / "file-000.parquet").write_bytes(frames)
    return path


def _cli(capsys, *argv: str) -> tuple[int, str, str]:
    code = datasets_main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# -- ids the filesystem cannot hold ---------------------------------------------------------------
def test_an_over_long_dataset_id_is_refused_by_the_run_config_in_one_line():
    with pytest.raises(RunConfigError) as err:
        RunConfig.of(compose(["policy=scripted", "benchmark=pick_v1", f"dataset_id={LONG}/name"]))
    (line,) = err.value.problems
    assert line.startswith("dataset_id: dataset id 'xxx") and "(305 characters) is too long" in line
    assert len(line) < 250


@pytest.mark.parametrize("namespace", [LONG, "/".join(["y" * 250] * 20)], ids=["a part", "the whole path"])
def test_create_refuses_a_namespace_the_filesystem_cannot_hold(home, capsys, namespace):
    code, _, err = _cli(capsys, "create", namespace)
    assert code == 2 and err.count("\n") == 1 and len(err) < 300, err
    assert err.startswith("molmo-datasets: error: namespace 'yyy" if "/" in namespace else
                          "molmo-datasets: error: namespace 'xxx") and "too long" in err
    assert not home.exists() or not any(home.iterdir())


# -- links and FIFOs ------------------------------------------------------------------------------
def test_a_link_on_the_dataset_id_path_is_refused_before_the_run(home, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    home.mkdir(parents=True)
    (home / "molmo").symlink_to(elsewhere)
    with pytest.raises(RecordConfigError, match=r"^dataset id 'molmo/evals/x': .*/molmo is a symlink; the store "
                                                r"never goes through one$"):
        LeRobotRecorderFactory.from_config(RunConfig.of(compose(["policy=scripted", "benchmark=pick_v1",
                                                    "dataset_id=molmo/evals/x"])))
    assert not any(elsewhere.iterdir())


def test_push_reads_nothing_through_a_link(home, tmp_path, hub_standin, monkeypatch, capsys):
    from huggingface_hub import HfApi

    monkeypatch.setenv("MOLMO_DATASETS_REMOTE", "hf://molmo-test")
    secret = tmp_path / "secret.txt"
    secret.write_text('{"token": "hf_secret"}')
    store = DatasetStore()
    store.create_namespace("molmo/evals")
    store.add_dataset("molmo/evals/run-a", _fake_dataset(tmp_path / "r" / "dataset"), {})
    meta = home / "molmo" / "evals" / "namespace_metadata.json"
    meta.unlink()
    meta.symlink_to(secret)  # a namespace whose metadata file is a link out of the store
    assert _cli(capsys, "push", "molmo/evals") == (2, "", "molmo-datasets: error: namespace 'molmo/evals' cannot be "
                                                          f"used: {meta} is a symlink; the store never goes through "
                                                          "one\n")
    _fake_dataset(tmp_path / "outside")
    (home / "molmo" / "linked").symlink_to(tmp_path / "outside")  # a dataset that is a link
    with pytest.raises(NamespaceError, match=r"^dataset 'molmo/linked' cannot be used: .*/molmo/linked is a symlink"):
        ns.upload_dataset("molmo/linked")
    meta.unlink()
    meta.write_text("{}")
    data = home / "molmo" / "evals" / "run-a" / "data"
    (data / "stolen.parquet").symlink_to(secret)  # links and FIFOs inside a dataset
    with pytest.raises(NamespaceError, match=r"/data/stolen.parquet is a symlink; refusing to read it$"):
        ns.upload_dataset("molmo/evals/run-a")
    (data / "stolen.parquet").unlink()
    os.mkfifo(data / "pipe.parquet")
    with pytest.raises(NamespaceError, match=r"/data/pipe.parquet is not a regular file; refusing to read it$"):
        ns.upload_dataset("molmo/evals/run-a")
    uploaded = [f.rfilename for repo in HfApi().list_datasets(author="molmo-test")
                for f in HfApi().dataset_info(repo.id).siblings or []]
    assert uploaded == []  # each push was refused before anything went up


def test_a_malformed_or_fifo_dataset_metadata_is_one_line_and_never_hangs_list(home, tmp_path, capsys):
    for name, text in (("typed", '{"benchmark": "pick_v1", "policy": ["a"], "success_rate": true}'),
                       ("listed", "[1, 2]"), ("broken", "{"), ("escaped", '{"policy": "\\u001b[31mred\\nline"}')):
        path = _fake_dataset(home / "molmo" / name)
        (path / "meta" / "eval").mkdir()
        (path / "meta" / "eval" / "dataset_metadata.json").write_text(text)
    fifo = _fake_dataset(home / "molmo" / "fifo")
    (fifo / "meta" / "eval").mkdir()
    os.mkfifo(fifo / "meta" / "eval" / "dataset_metadata.json")
    proc = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.datasets", "--root", str(home), "list"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[1:] == [
        "dataset    molmo/broken", "dataset    molmo/escaped  None · '\\x1b[31mred\\nline'", "dataset    molmo/fifo",
        "dataset    molmo/listed", "dataset    molmo/typed  None · ['a']"]
    warned = proc.stderr.splitlines()
    assert len(warned) == 3 and all(w.startswith("molmo-datasets: warning: dataset 'molmo/") for w in warned)
    assert "dataset_metadata.json is not a regular file; refusing to read through it" in warned[1]
    code, _, err = _cli(capsys, "--root", str(home), "show", "molmo/fifo")
    assert code == 2 and err.count("\n") == 1 and "is not a regular file" in err


# -- what a pull brings ---------------------------------------------------------------------------
def test_a_pulled_dataset_never_decides_which_local_run_resume_or_compare_use(home, tmp_path, hub_standin,
                                                                              monkeypatch):
    from huggingface_hub import HfApi

    from molmo_lerobot.errors import RunError
    from molmo_lerobot.runner.evaluate import _stored_run_dir

    monkeypatch.setenv("MOLMO_DATASETS_REMOTE", "hf://molmo-test")
    victim = tmp_path / "victim-run"  # another local run, whose results a hostile remote would have rewritten
    victim.mkdir()
    store = DatasetStore()
    store.add_dataset("molmo/evals/run-a", _fake_dataset(tmp_path / "r" / "dataset"), {}, run_dir=tmp_path / "r")
    assert store.run_dir("molmo/evals/run-a") == (tmp_path / "r").resolve()
    ns.upload_dataset("molmo/evals/run-a")
    api = HfApi()
    for planted in ("evals/run-a/.molmo_run_dir", "evals/run-a/.run_dirs/molmo/evals/run-a.json"):
        api.upload_file(path_or_fileobj=str(victim).encode(), path_in_repo=planted, repo_id="molmo-test/molmo",
                        repo_type="dataset")
    # a fresh store: the pulled dataset keeps no hidden file and names no local run
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "fresh"))
    fresh = DatasetStore()
    pulled = ns.download_dataset("molmo/evals/run-a")
    assert not [p for p in pulled.rglob(".*")]
    with pytest.raises(NamespaceError, match="was not recorded into this store by molmo-eval"):
        fresh.run_dir("molmo/evals/run-a")
    with pytest.raises(NamespaceError, match="was not recorded into this store"):
        ns.resolve_run("molmo/evals/run-a")
    with pytest.raises(RunError, match=r"^cannot resume dataset_id=molmo/evals/run-a: dataset 'molmo/evals/run-a'"):
        _stored_run_dir("molmo/evals/run-a")
    # the first store: its recording, replaced by a pull, no longer names the run that recorded it
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "home"))
    ns.download_dataset("molmo/evals/run-a", force_download=True)
    with pytest.raises(NamespaceError, match="was not recorded into this store"):
        store.run_dir("molmo/evals/run-a")
    assert not (home / ".run_dirs" / "molmo" / "evals" / "run-a.json").exists()


def test_a_hostile_remotes_metadata_is_refused_or_shown_escaped(home, tmp_path, hub_standin, monkeypatch, capsys):
    from huggingface_hub import HfApi

    api = HfApi()
    for repo, text in (("molmo-test/molmo", json.dumps({
            "namespaces": ["molmo/ok", "molmo/\x1b[31mred", "molmo/../../etc", 5, "other/ns"],
            "datasets": ["molmo/ok/run", "molmo/x\ny", "other/z"]})), ("molmo-test/junk", "{not json"),
                       ("molmo-test/listy", "[1]")):
        api.create_repo(repo, repo_type="dataset")
        api.upload_file(path_or_fileobj=text.encode(), path_in_repo="namespace_metadata.json", repo_id=repo,
                        repo_type="dataset")
    code, out, err = _cli(capsys, "list", "--remote", "hf://molmo-test")
    assert code == 0
    assert out.splitlines() == ["# hf://molmo-test", "namespace  molmo", "namespace  molmo/ok",
                                "dataset    molmo/ok/run"]
    lines = err.splitlines()
    assert len(lines) == 8 and all(line.startswith("molmo-datasets: warning: ") for line in lines)
    assert "\x1b" not in err and "'molmo/\\x1b[31mred'" in err and "'molmo/x\\ny'" in err
    assert "'molmo-test/junk' on the Hub: namespace_metadata.json is not valid JSON" in err
    assert "'molmo-test/listy' on the Hub: namespace_metadata.json is not a JSON object; skipped" in err
    assert "'other/z' is not in its namespace 'molmo'" in err
    # a push that would rewrite a registration it cannot read is one line, and changes nothing there
    api.upload_file(path_or_fileobj=b'{"datasets": "molmo/a"}', path_in_repo="namespace_metadata.json",
                    repo_id="molmo-test/molmo", repo_type="dataset")
    DatasetStore().add_dataset("molmo/evals/run-b", _fake_dataset(tmp_path / "r" / "dataset"), {})
    code, _, err = _cli(capsys, "push", "molmo/evals/run-b", "--remote", "hf://molmo-test")
    assert code == 2 and err == ("molmo-datasets: error: 'molmo-test/molmo' on the Hub: 'datasets' in its "
                                 "namespace_metadata.json is not a list of ids\n")


# -- staging left by killed processes ------------------------------------------------------------
def test_stale_staging_folders_are_swept_unless_held_or_recent(home, tmp_path):
    store = DatasetStore()
    home.mkdir(parents=True)
    old = time.time() - 2 * 3600  # past STALE_STAGING_S
    for name in ("stale", "held", "recent"):
        (home / f".incoming-{name}" / "dataset").mkdir(parents=True)
        (home / f".incoming-{name}" / "dataset" / "part.bin").write_bytes(b"x")
        if name != "recent":
            os.utime(home / f".incoming-{name}", (old, old))
    held = os.open(home / ".incoming-held", os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(held, fcntl.LOCK_EX)  # a copy still in progress, however old
        store.add_dataset("molmo/run", _fake_dataset(tmp_path / "r" / "dataset"), {})
    finally:
        os.close(held)
    assert sorted(p.name for p in home.iterdir() if p.name.startswith(".incoming-")) == [
        ".incoming-held", ".incoming-recent"]
    assert store.is_dataset("molmo/run")


# -- the CLI --------------------------------------------------------------------------------------
def test_show_prints_a_datasets_summary_and_set_refuses_the_reserved_keys(home, tmp_path, capsys):
    store = DatasetStore()
    store.add_dataset("molmo/evals/run-a", _fake_dataset(tmp_path / "r" / "dataset"), {"policy": "scripted"},
                      run_dir=tmp_path / "r")
    code, out, _ = _cli(capsys, "show", "molmo/evals/run-a")
    assert code == 0
    assert json.loads(out) == {
        "dataset_id": "molmo/evals/run-a", "path": str(home / "molmo" / "evals" / "run-a"),
        "run_dir": str((tmp_path / "r").resolve()), "codebase_version": "v3.0", "robot_type": None, "fps": 10,
        "total_episodes": 2, "total_frames": None, "total_tasks": None,
        "metadata": {"dataset_id": "molmo/evals/run-a", "policy": "scripted"}}
    code, out, _ = _cli(capsys, "show", "molmo/evals")
    assert code == 0 and json.loads(out) == {}
    assert _cli(capsys, "show", "molmo/nope") == (2, "", f"molmo-datasets: error: no namespace or dataset "
                                                        f"'molmo/nope' in {home}\n")
    for key, why in (("namespace", "it is the namespace's id"), ("description", "give it with --description")):
        assert _cli(capsys, "create", "molmo/other", "--set", f"{key}=x") == (
            2, "", f"molmo-datasets: error: --set '{key}=x': '{key}' is not a metadata key here ({why})\n")
    assert not store.is_namespace("molmo/other")
