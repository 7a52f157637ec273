"""``molmo-eval record=true dataset_id=ns/sub/name``: recordings go into the dataset store by namespace, load
with ``LeRobotDataset``, are found again by their id (resume, molmo-compare), and travel through the Hub."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from molmo_lerobot import namespaces as ns
from molmo_lerobot.cli.eval import _stored_lines
from molmo_lerobot.config import compose
from molmo_lerobot.export.recorder import RecordConfigError
from molmo_lerobot.run_config import RunConfig, RunConfigError
from molmo_lerobot.runner.evaluate import run_evaluation

TINY = ["policy=scripted", "benchmark=pick_v1", "workers=1", "limit=1", "horizon=4", "progress=false",
        "video.vcodec=h264"]


@pytest.fixture
def store(tmp_path, monkeypatch):
    monkeypatch.delenv("MOLMO_DATASETS_PATH", raising=False)
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "home"))
    return ns.DatasetStore()


def _load(dataset_id, root):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(dataset_id, root=root, video_backend="pyav")


def test_a_recording_goes_into_its_namespace_and_loads(store, tmp_path, fork_servers):
    out = tmp_path / "run"
    res = run_evaluation(compose([*TINY, f"output_dir={out}", "dataset_id=molmo/evals/pick/tiny"]), fork_servers)
    assert res.summary["n_episodes"] == 1
    assert store.list_local_namespaces() == ["molmo", "molmo/evals", "molmo/evals/pick"]
    meta = store.list_local_datasets()["molmo/evals/pick/tiny"]
    assert meta["benchmark"]["name"] == "pick_v1" and len(meta["benchmark"]["sha256"]) == 64
    assert meta["policy"] == "scripted" and meta["run_id"] == "run" and meta["n_episodes"] == 1
    stored = _load("molmo/evals/pick/tiny", store.path("molmo/evals/pick/tiny"))
    local = _load("local/pick_v1-scripted", out / "dataset")  # the run directory keeps its own (a copy)
    assert stored.num_episodes == local.num_episodes == 1 and len(stored) == len(local) == 4
    assert store.run_dir("molmo/evals/pick/tiny") == out.resolve()
    assert _stored_lines(res.summary) == [f"stored: {store.path('molmo/evals/pick/tiny')} (dataset_id=molmo/evals/"
                                          "pick/tiny; molmo-datasets show molmo/evals/pick/tiny)"]  # molmo-eval says
    # another run may not take the id: one line, before any run directory, nothing in the store changed
    before = sorted(p.relative_to(store.root) for p in store.root.rglob("*"))
    with pytest.raises(RecordConfigError) as err:
        run_evaluation(compose([*TINY, f"output_dir={tmp_path / 'other'}", "dataset_id=molmo/evals/pick/tiny"]),
                       fork_servers)
    assert str(err.value) == (f"dataset id 'molmo/evals/pick/tiny' collides with an existing dataset in {store.root} "
                              "(pick another id, or delete that dataset first)")
    assert not (tmp_path / "other").exists()
    assert sorted(p.relative_to(store.root) for p in store.root.rglob("*")) == before


@pytest.mark.parametrize("bad", ["molmo//x", "molmo/evals/", "a/x", "molmo/.hidden"])
def test_bad_dataset_ids_are_one_line_before_any_run(store, bad):
    with pytest.raises(RunConfigError) as err:
        RunConfig.of(compose([*TINY, f"dataset_id={bad}"]))
    (line,) = err.value.problems
    assert line.startswith(f"dataset_id: malformed dataset id {bad!r}")


@pytest.mark.parametrize(("dataset_id", "error"), [
    ("molmo//x", "dataset_id: malformed dataset id 'molmo//x': malformed namespace 'molmo/': use letters, digits, "
                 "'-', '_' and '/' between parts (at least 2 characters, no leading, trailing or double '/')"),
    # the id check once raised ENAMETOOLONG inside the recorder hook, which was skipped: the run scored, exit 0,
    # and its recording was dropped
    ("x" * 300 + "/name", f"dataset_id: dataset id {'x' * 60!r}… (305 characters) is too long: its part "
                          f"{'x' * 60!r}… (300 characters) has 300 bytes, and a file name at most 255"),
], ids=["malformed", "too long"])
def test_molmo_eval_refuses_a_bad_dataset_id_with_one_line_and_exit_2(store, tmp_path, dataset_id, error):
    proc = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.eval", *TINY, f"output_dir={tmp_path / 'run'}",
                           f"dataset_id={dataset_id}"], capture_output=True, text=True,
                          env={**os.environ, "MUJOCO_GL": "egl"}, timeout=300)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [f"molmo-eval: error: {error}"]
    assert not (tmp_path / "run").exists() and not store.root.exists()


@pytest.mark.slow
def test_two_runs_recorded_listed_pushed_pulled_and_loaded(store, tmp_path, hub_standin, monkeypatch):
    runs = {}
    for name, policy in (("scripted", "scripted"), ("random", "random")):
        out = tmp_path / name
        argv = [*TINY, f"policy={policy}", f"output_dir={out}", f"dataset_id=molmo/evals/pick_v1/{name}",
                "push=true", "hub.remote=hf://molmo-test"]
        res = run_evaluation(compose(argv))
        assert res.summary["push"] == {"repo_id": f"hf://molmo-test/molmo/evals/pick_v1/{name}", "ok": True,
                                       "error": None}
        runs[name] = out
    cli = [sys.executable, "-m", "molmo_lerobot.cli.datasets"]
    env = {**os.environ, "MUJOCO_GL": "egl"}
    listed = subprocess.run([*cli, "list"], capture_output=True, text=True, env=env, check=True).stdout
    assert "dataset    molmo/evals/pick_v1/random  pick_v1 · random" in listed
    assert "namespace  molmo/evals/pick_v1" in listed
    remote = subprocess.run([*cli, "list", "--remote", "hf://molmo-test"], capture_output=True, text=True, env=env,
                            check=True).stdout.splitlines()
    assert remote == ["# hf://molmo-test", "namespace  molmo", "namespace  molmo/evals",
                      "namespace  molmo/evals/pick_v1",
                      "dataset    molmo/evals/pick_v1/random", "dataset    molmo/evals/pick_v1/scripted"]
    # runs are found again by their dataset ids
    compare = subprocess.run([sys.executable, "-m", "molmo_lerobot.cli.compare", "molmo/evals/pick_v1/scripted",
                              "molmo/evals/pick_v1/random", "--json"], capture_output=True, text=True, env=env)
    assert compare.returncode == 0, compare.stderr
    assert json.loads(compare.stdout)["n_shared"] == 1
    # resume finds the run by its dataset id and replaces its own recording in the store and on the Hub
    again = run_evaluation(compose([*TINY, "resume=true", "dataset_id=molmo/evals/pick_v1/scripted", "push=true",
                                    "hub.remote=hf://molmo-test"]))
    assert again.output_dir.resolve() == runs["scripted"].resolve() and again.summary["push"]["ok"]
    # a fresh home: namespace metadata, then both datasets pulled and loaded
    monkeypatch.setenv("MOLMO_LEROBOT_HOME", str(tmp_path / "fresh"))
    monkeypatch.setenv("MOLMO_DATASETS_REMOTE", "hf://molmo-test")
    ns.download_namespace_metadata("molmo/evals/pick_v1")
    assert ns.list_local_namespaces() == ["molmo/evals/pick_v1"]
    fresh = ns.DatasetStore()
    for name, out in runs.items():
        ns.download_dataset(f"molmo/evals/pick_v1/{name}")
        got = _load(f"molmo/evals/pick_v1/{name}", fresh.path(f"molmo/evals/pick_v1/{name}"))
        assert got.num_episodes == 1 and len(got) == len(_load("x/y", out / "dataset"))
    assert ns.list_local_namespaces() == ["molmo/evals/pick_v1"]
    assert sorted(fresh.list_local_datasets()) == ["molmo/evals/pick_v1/random", "molmo/evals/pick_v1/scripted"]
