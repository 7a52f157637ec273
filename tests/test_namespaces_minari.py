"""Differential: Minari's own ``minari.namespace`` and ours run the same random sequences of create /
update / get / nest / delete / list / validate / hierarchy (malformed ids included, and datasets put
into namespaces) on two empty stores; every call must give the same outcome (value, builtin exception
class, warning) and leave the same files. Minari writes under ``MINARI_DATASETS_PATH``."""

from __future__ import annotations

import json
import random
import warnings
from collections import Counter
from pathlib import Path

import pytest

from molmo_lerobot import namespaces as ours

minari_ns = pytest.importorskip("minari.namespace")

NAMESPACES = ["ab", "ab/cd", "ab/cd/ef", "xy", "xy/z_1", "ab-1/c_2", "é_1",  # valid
              "a", "", "a b", "/ab", "ab/", "dot.ted", "-/-", "__"]  # malformed, and odd but valid
DATASETS = ["ab/cd/run1", "xy/run2", "ab/run3"]  # never a namespace id, never a parent of one
DESCRIPTIONS = [None, "pick runs", "ünïcode"]
KWARGS = [{}, {"owner": "me"}, {"n": 3, "tags": ["a", "b"]}]


def _outcome(fn, *args, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            value = fn(*args, **kwargs)
            value = list(value) if not isinstance(value, dict | type(None)) else value
            result = ("ok", value)
        except (TypeError, ValueError) as exc:
            result = ("raise", TypeError if isinstance(exc, TypeError) else ValueError)
    return result, [w.category for w in caught if issubclass(w.category, UserWarning)]


def _tree(root: Path, dataset_marker: str) -> dict[str, bytes | None]:
    """Files and directories below ``root``, without the insides of datasets (each store has its own format)."""
    out: dict[str, bytes | None] = {}
    datasets = {p.parent.parent for p in root.rglob(Path(dataset_marker).name)
                if p.relative_to(root).as_posix().endswith(dataset_marker)}
    for p in sorted(root.rglob("*")):
        if any(d in p.parents for d in datasets):
            continue
        out[p.relative_to(root).as_posix()] = p.read_bytes() if p.is_file() else None
    return out


def _add_dataset_minari(dataset_id: str, root: Path) -> None:
    """What Minari's ``create_dataset_from_buffers`` does to namespaces (minari/utils.py), then its ``data/``."""
    namespace = dataset_id.rpartition("/")[0]
    if namespace not in minari_ns.list_local_namespaces():
        minari_ns.create_namespace(namespace)
    (root / dataset_id / "data").mkdir(parents=True)
    (root / dataset_id / "data" / "main_data.hdf5").write_bytes(b"x")


def _add_dataset_ours(dataset_id: str, src: Path) -> None:
    ours.DatasetStore().add_dataset(dataset_id, src, {})


def _step(rng: random.Random):
    op = rng.choice(["create", "create", "update", "get", "delete", "delete", "list", "validate", "hierarchy",
                     "dataset", "drop_dataset"])
    ident = rng.choice(NAMESPACES)
    if op in ("create", "update"):
        return op, (ident, rng.choice(DESCRIPTIONS)), dict(rng.choice(KWARGS))
    if op in ("dataset", "drop_dataset"):
        return op, (rng.choice(DATASETS),), {}
    if op == "list":
        return op, (), {}
    return op, (ident,), {}


def _run_sequences(tmp_path, monkeypatch, seeds: range) -> None:
    import shutil

    src = tmp_path / "src_dataset"
    (src / "meta").mkdir(parents=True)
    (src / "meta" / "info.json").write_text("{}")
    calls = {"create": (minari_ns.create_namespace, ours.create_namespace),
             "update": (minari_ns.update_namespace_metadata, ours.update_namespace_metadata),
             "get": (minari_ns.get_namespace_metadata, ours.get_namespace_metadata),
             "delete": (minari_ns.delete_namespace, ours.delete_namespace),
             "list": (minari_ns.list_local_namespaces, ours.list_local_namespaces),
             "validate": (minari_ns.validate_namespace, ours.validate_namespace),
             "hierarchy": (minari_ns.namespace_hierarchy, ours.namespace_hierarchy)}
    counts: Counter = Counter()
    outcomes: Counter = Counter()
    for seq in seeds:
        rng = random.Random(seq)
        mroot, oroot = tmp_path / f"minari{seq}", tmp_path / f"ours{seq}"
        monkeypatch.setenv("MINARI_DATASETS_PATH", str(mroot))
        monkeypatch.setenv("MOLMO_DATASETS_PATH", str(oroot))
        for _ in range(30):
            op, args, kwargs = _step(rng)
            if op == "dataset":
                ident = args[0]
                if (mroot / ident).exists():
                    continue  # Minari's own writer refuses an existing id too
                _add_dataset_minari(ident, mroot)
                _add_dataset_ours(ident, src)
            elif op == "drop_dataset":  # Minari's delete_dataset: remove the dataset directory
                shutil.rmtree(mroot / args[0], ignore_errors=True)
                shutil.rmtree(oroot / args[0], ignore_errors=True)
            else:
                theirs = _outcome(calls[op][0], *args, **kwargs)
                mine = _outcome(calls[op][1], *args, **kwargs)
                assert mine == theirs, (seq, op, args, kwargs)
                outcomes[theirs[0][0] if not theirs[1] else "warn"] += 1
            counts[op] += 1
            assert _tree(oroot, "meta/info.json") == {k: v for k, v in _tree(mroot, "data/main_data.hdf5").items()
                                                      if k or v is not None}, (seq, op, args)
        shutil.rmtree(mroot, ignore_errors=True)
        shutil.rmtree(oroot, ignore_errors=True)
    print(f"\nminari differential: {sum(counts.values())} calls in {len(seeds)} sequences: "
          f"{dict(sorted(counts.items()))}; "
          f"outcomes {dict(outcomes)}")
    assert all(counts[op] > len(seeds) for op in calls)
    assert outcomes["raise"] > 10 * len(seeds) and outcomes["warn"] > len(seeds)


def test_random_sequences_match_minari(tmp_path, monkeypatch):
    _run_sequences(tmp_path, monkeypatch, range(20))


@pytest.mark.slow
def test_many_random_sequences_match_minari(tmp_path, monkeypatch):
    _run_sequences(tmp_path, monkeypatch, range(20, 320))


def test_deliberate_differences(tmp_path, monkeypatch):
    """Where we refuse what Minari accepts: an empty part (``a//b``: Minari creates ``a/b`` and then cannot find
    ``a//b``, so a second create overwrites it) and a namespace inside a dataset (Minari writes into it)."""
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "m"))
    monkeypatch.setenv("MOLMO_DATASETS_PATH", str(tmp_path / "o"))
    minari_ns.create_namespace("a//b", description="first")
    minari_ns.create_namespace("a//b", description="second")  # no "already exists"
    assert "a//b" not in minari_ns.list_local_namespaces()
    with pytest.raises(ours.NamespaceError, match="malformed namespace 'a//b'"):
        ours.create_namespace("a//b")
    (tmp_path / "m" / "ns" / "ds" / "data").mkdir(parents=True)
    minari_ns.create_namespace("ns/ds")
    assert (tmp_path / "m" / "ns" / "ds" / "namespace_metadata.json").is_file()  # inside the dataset
    (tmp_path / "o" / "ns" / "ds" / "meta").mkdir(parents=True)
    (tmp_path / "o" / "ns" / "ds" / "meta" / "info.json").write_text("{}")
    with pytest.raises(ours.NamespaceError, match="collides with the dataset 'ns/ds'"):
        ours.create_namespace("ns/ds")


def test_the_hub_layout_is_minaris(tmp_path, monkeypatch, hub_standin):
    """Minari's own Hugging Face storage and ours upload the same nested namespaces (parents first) to the
    Hub stand-in: the same repos, files and namespace metadata; each lists the other's namespaces."""
    def repos(owner):  # read from the stand-in's store: Minari writes into the client's cached files
        out = {}
        for (kind, repo_id), repo in hub_standin.repos.items():
            if kind == "dataset" and repo_id.startswith(owner + "/"):
                for path, (sha256, *_) in repo.files("main").items():
                    data = json.loads(hub_standin.blob(sha256).read_bytes())
                    out[(repo_id.split("/", 1)[1], path)] = {k: sorted(v) if isinstance(v, list) else v
                                                             for k, v in data.items()}
        return out

    for env, root in (("MINARI_DATASETS_PATH", tmp_path / "m"), ("MOLMO_DATASETS_PATH", tmp_path / "o")):
        monkeypatch.setenv(env, str(root))
    for create in (minari_ns.create_namespace, ours.create_namespace):
        create("molmo/evals/pick", description="pick runs", owner="me")
        create("molmo/other")
        create("solo_ns", description="top only")
    monkeypatch.setenv("MINARI_REMOTE", "hf://minari-side")
    monkeypatch.setenv("MOLMO_DATASETS_REMOTE", "hf://ours-side")
    for namespace in ("molmo/evals/pick", "molmo/other", "solo_ns"):
        minari_ns.upload_namespace(namespace, token="unused")
        ours.upload_namespace(namespace)
    assert repos("ours-side") == repos("minari-side") and len(repos("ours-side")) == 5
    assert sorted(ours.list_remote_namespaces()) == sorted(minari_ns.list_remote_namespaces())
    monkeypatch.setenv("MOLMO_DATASETS_REMOTE", "hf://minari-side")  # ours reads what Minari uploaded
    assert sorted(ours.list_remote_namespaces()) == ["molmo", "molmo/evals", "molmo/evals/pick", "molmo/other",
                                                     "solo_ns"]
