"""MolmoSpaces' remote layouts (HTTP bucket, Hub tar shards read with Range requests), their
on-disk cache/install layout, the ``--preset molmospaces`` version table and faults (issue 15)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from molmo_lerobot.cli.resources import main
from molmo_lerobot.resources import ResourceManager
from molmo_lerobot.resources import molmospaces as ms

try:
    from ms_remotes import BucketStandin, publish_bucket, publish_hf
except ImportError:
    from tests.resources.ms_remotes import BucketStandin, publish_bucket, publish_hf

REPO = "allenai-standin/molmospaces"
HF = f"hf://datasets/{REPO}/mujoco"


@pytest.fixture
def bucket(tmp_path):
    with BucketStandin(tmp_path / "bucket") as b:
        yield b


def _objects_tree(root, n=6, tag="v1"):
    """Objaverse-like objects: one directory per UID (the UID is the first path component)."""
    for i in range(n):
        uid = f"{i:02d}aa{i}bb"
        (root / uid / "meshes").mkdir(parents=True)
        (root / uid / f"{uid}.xml").write_text(f"<mujoco model='{uid}' tag='{tag}'/>\n")
        (root / uid / "meshes" / "m.obj").write_bytes(os.urandom(3000 + i))
    return root


def _scenes_tree(root, tag="v1"):
    (root / "sub").mkdir(parents=True)
    for i in range(3):
        (root / f"train_{i}.xml").write_text(f"<mujoco model='train_{i}' tag='{tag}'/>\n")
    (root / "sub" / "shared.png").write_bytes(os.urandom(500))
    (root / "train_0_link.xml").symlink_to("train_0.xml")
    return root


def _data(root):
    """``{rel: bytes}`` of the data files under ``root``, without MolmoSpaces' metadata files and flags."""
    out = {}
    for dirpath, _dirs, files in os.walk(root, followlinks=True):
        for f in files:
            rel = os.path.relpath(os.path.join(dirpath, f), root)
            if not ms.is_own_file(rel) and not rel.endswith("_complete_links"):
                out[rel] = Path(dirpath, f).read_bytes()
    return out


def _scene_group(rel):
    """Numbered scene archives (``ithor_0``, …) plus a base archive, as their scene datasets are split."""
    return "base" if "/" in rel else rel.split("_")[1][:1]


def _install(tmp_path, remote, *args, cache="cache", install="install"):
    return main(["install", *args, "--remote", remote, "--cache-dir", str(tmp_path / cache),
                 "--install-dir", str(tmp_path / install), "--no-progress"])


def _their_layout_ok(tmp_path, spec, archives, cache="cache", install="install"):
    """What molmospaces-resources expects on disk after an install of ``spec``."""
    data_type, rest = spec.split("/")
    source, version = rest.split("@")
    vdir = tmp_path / cache / data_type / source / version
    assert (vdir / ms.REMOTE_MANIFEST).is_file() and (vdir / ms.TRIES).is_file()
    for a in archives:
        assert (vdir / f".{a}_complete_extract").is_file()
    cache_manifest = json.loads((tmp_path / cache / ms.LOCAL_MANIFEST).read_text())
    assert version in cache_manifest[data_type][source]
    link_manifest = json.loads((tmp_path / install / ms.LOCAL_MANIFEST).read_text())
    assert link_manifest[data_type][source] == version
    inst = tmp_path / install / data_type / source
    tries = (inst / ms.TRIES).resolve()
    assert tries.is_file() and tries.parent.name == version  # their "already installed" test
    return vdir, inst


# -- both remotes: eager, on demand by UID, exact files through version-free paths -------------------------------
@pytest.mark.parametrize("kind", ["bucket", "hf"])
def test_eager_and_uid_installs_give_exact_files(kind, bucket, hub_standin, tmp_path, read_tree):
    objects = _objects_tree(tmp_path / "objects_src")
    groups = publish_bucket(objects, bucket.root, "objects", "objaverse", "20260131")
    scenes = _scenes_tree(tmp_path / "scenes_src")
    publish_bucket(scenes, bucket.root, "scenes", "ithor", "20251217", group=_scene_group)
    if kind == "hf":
        rows = publish_hf(hub_standin, bucket.root, REPO, "mujoco", "objects", "objaverse", "20260131")
        publish_hf(hub_standin, bucket.root, REPO, "mujoco", "scenes", "ithor", "20251217")
    remote = bucket.url if kind == "bucket" else HF

    assert _install(tmp_path, remote, "objects/objaverse@20260131", "scenes/ithor@20251217") == 0
    assert _data(tmp_path / "install" / "objects" / "objaverse") == read_tree(objects)
    if kind == "hf":  # an eager install reads each archive's bytes once, by Range, never whole shards
        sent = sum(n for p, n in hub_standin.sent.items() if p.startswith("mujoco/objects/objaverse/20260131/shards/"))
        assert sent == sum(r["size"] for r in rows.values())
    scenes_inst = tmp_path / "install" / "scenes" / "ithor"
    assert not scenes_inst.is_symlink() and (scenes_inst / "train_1.xml").is_symlink()  # their PER_FILE
    assert _data(scenes_inst) == read_tree(scenes)
    _their_layout_ok(tmp_path, "objects/objaverse@20260131", groups)
    assert ResourceManager(tmp_path / "cache", tmp_path / "install").verify() == []

    # on demand: one UID fetches exactly its archive
    uid = "03aa3bb"
    before = dict(bucket.archive_gets()) if kind == "bucket" else dict(hub_standin.sent)
    assert _install(tmp_path, remote, "objects/objaverse@20260131", "--uid", uid, cache="c2", install="i2") == 0
    inst = tmp_path / "i2" / "objects" / "objaverse"
    assert read_tree(inst / uid) == read_tree(objects / uid)
    assert not (inst / "00aa0bb").exists()
    archive = f"objaverse_{uid}.tar.zst"
    if kind == "bucket":
        fetched = {p: n - before.get(p, 0) for p, n in bucket.archive_gets().items() if n != before.get(p, 0)}
        assert fetched == {f"objects/objaverse/20260131/{archive}": 1}
    else:
        fetched = {p: n - before.get(p, 0) for p, n in hub_standin.sent.items()
                   if "/shards/" in p and n != before.get(p, 0)}
        shard = f"mujoco/objects/objaverse/20260131/shards/{rows[archive]['shard_id']:05d}.tar"
        assert fetched == {shard: rows[archive]["size"]}  # exactly the archive's bytes, by Range
        shard_size = len(hub_standin.read_file("dataset", REPO, shard))
        print(f"\nRange read: {rows[archive]['size']} bytes of a {shard_size}-byte shard for UID {uid}")
        assert rows[archive]["size"] < shard_size / 2


def test_second_version_installs_beside_and_links_move(bucket, tmp_path, read_tree):
    v1, v2 = _objects_tree(tmp_path / "o1", 3, "v1"), _objects_tree(tmp_path / "o2", 4, "v2")
    s1, s2 = _scenes_tree(tmp_path / "s1", "v1"), _scenes_tree(tmp_path / "s2", "v2")
    for tree, version in ((v1, "1"), (v2, "2")):
        publish_bucket(tree, bucket.root, "objects", "thor", version)
    for tree, version in ((s1, "1"), (s2, "2")):
        publish_bucket(tree, bucket.root, "scenes", "ithor", version, group=_scene_group)
    assert _install(tmp_path, bucket.url, "objects/thor@1", "scenes/ithor@1") == 0
    assert _install(tmp_path, bucket.url, "objects/thor@2", "scenes/ithor@2") == 0
    inst = tmp_path / "install"
    assert os.readlink(inst / "objects" / "thor").endswith("/objects/thor/2")
    assert _data(inst / "objects" / "thor") == read_tree(v2)
    assert _data(inst / "scenes" / "ithor") == read_tree(s2)
    assert read_tree(tmp_path / "cache" / "objects" / "thor" / "1")["00aa0bb/00aa0bb.xml"].endswith(b"'v1'/>\n")
    assert json.loads((inst / ms.LOCAL_MANIFEST).read_text()) == {"objects": {"thor": "2"}, "scenes": {"ithor": "2"}}
    assert json.loads((tmp_path / "cache" / ms.LOCAL_MANIFEST).read_text()) == {
        "objects": {"thor": ["1", "2"]}, "scenes": {"ithor": ["1", "2"]}}
    assert ResourceManager(tmp_path / "cache", inst).verify() == []


@pytest.mark.parametrize("kind", ["bucket", pytest.param("hf", marks=pytest.mark.slow)])
def test_four_concurrent_installers_do_the_work_once(kind, bucket, hub_standin, tmp_path, read_tree):
    objects = _objects_tree(tmp_path / "src", 10)
    groups = publish_bucket(objects, bucket.root, "objects", "objaverse", "1")
    if kind == "hf":
        publish_hf(hub_standin, bucket.root, REPO, "mujoco", "objects", "objaverse", "1")
    remote = bucket.url if kind == "bucket" else HF
    env = {**os.environ}
    cmd = [sys.executable, "-m", "molmo_lerobot.cli.resources", "install", "objects/objaverse@1", "--remote", remote,
           "--cache-dir", str(tmp_path / "cache"), "--install-dir", str(tmp_path / "install"), "--no-progress",
           "--workers", "2"]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
             for _ in range(4)]
    outs = [p.communicate(timeout=180) for p in procs]
    assert [p.returncode for p in procs] == [0] * 4, [o[1] for o in outs]
    extracted = sorted(int(re.search(r"(\d+) archives extracted", o[0]).group(1)) for o in outs)
    assert extracted == [0, 0, 0, len(groups)], extracted
    if kind == "bucket":
        assert set(bucket.archive_gets().values()) == {1} and len(bucket.archive_gets()) == len(groups)
    else:
        shard_reads = [r for r in hub_standin.ranges if "/shards/" in r[0]]
        assert len(shard_reads) == len(set(shard_reads)) == len(groups)
    assert _data(tmp_path / "install" / "objects" / "objaverse") == \
        read_tree(objects)


# -- faults: one line, nothing that looks complete, retry succeeds ---------------------------------------------
def _fault_install(tmp_path, remote, capsys):
    rc = _install(tmp_path, remote, "objects/objaverse@1")
    return rc, capsys.readouterr().err


def _assert_failed_cleanly(tmp_path, rc, err, pattern):
    assert rc == 1 and err.count("\n") == 1 and "Traceback" not in err, err
    assert re.search(pattern, err), err
    vdir = tmp_path / "cache" / "objects" / "objaverse" / "1"
    assert len(list(vdir.glob(".*_complete_extract"))) < 4  # archives that did arrive may be flagged, …
    assert not ResourceManager(tmp_path / "cache", tmp_path / "install").is_complete("objects/objaverse@1")
    assert not (tmp_path / "install" / "objects" / "objaverse").exists()  # … but nothing is linked or complete


@pytest.mark.parametrize("fault", ["corrupt-shard", "wrong-offset", "inflated-size", "truncated", "404", "401"])
def test_hf_faults_are_one_line_and_retry_succeeds(fault, bucket, hub_standin, tmp_path, capsys, read_tree,
                                                   monkeypatch):
    objects = _objects_tree(tmp_path / "src", 4)
    (objects / "01aa1bb" / "big.bin").write_bytes(os.urandom(300_000))  # past the per-member header allowance
    publish_bucket(objects, bucket.root, "objects", "objaverse", "1")
    rows = publish_hf(hub_standin, bucket.root, REPO, "mujoco", "objects", "objaverse", "1")
    from huggingface_hub import HfApi

    api = HfApi()
    name = sorted(rows)[1]
    shard = f"mujoco/objects/objaverse/1/shards/{rows[name]['shard_id']:05d}.tar"
    table = "mujoco__objects__objaverse__1/pkgs-00000-of-00001.parquet"
    good_shard = hub_standin.read_file("dataset", REPO, shard)
    good_table = hub_standin.read_file("dataset", REPO, table)
    if fault == "corrupt-shard":
        bad = bytearray(good_shard)
        start = rows[name]["offset"]
        bad[start: start + 64] = bytes(64)
        api.upload_file(path_or_fileobj=bytes(bad), path_in_repo=shard, repo_id=REPO, repo_type="dataset")
        pattern = f"archive {re.escape(name)}: cannot be read"
    elif fault in ("wrong-offset", "inflated-size"):
        import io

        import pyarrow as pa
        import pyarrow.parquet as pq

        edit = {"offset": rows[name]["offset"] + 512} if fault == "wrong-offset" else {"inflated_size": 100}
        moved = [{**r, "inflated_size": 1 << 20, **(edit if r["path"] == name else {})} for r in rows.values()]
        buf = io.BytesIO()
        pq.write_table(pa.Table.from_pylist(moved), buf)
        api.upload_file(path_or_fileobj=buf.getvalue(), path_in_repo=table, repo_id=REPO, repo_type="dataset")
        pattern = (f"archive {re.escape(name)}: cannot be read" if fault == "wrong-offset"
                   else f"archive {re.escape(name)}: .*past its limit of .* bytes")
    elif fault == "truncated":
        hub_standin.faults[shard] = "truncate"
        pattern = "transfer of archive .* failed|truncated response"
    elif fault == "404":
        api.delete_file(shard, repo_id=REPO, repo_type="dataset")
        pattern = r"shards/0000\d\.tar not found \(HTTP 404\)"
    else:
        hub_standin.token = "secret-token-123"
        monkeypatch.delenv("HF_TOKEN", raising=False)
        monkeypatch.setenv("HF_HUB_DISABLE_IMPLICIT_TOKEN", "1")
        pattern = r"denied \(HTTP 401\); set HF_TOKEN"
    rc, err = _fault_install(tmp_path, HF, capsys)
    _assert_failed_cleanly(tmp_path, rc, err, pattern)
    assert "secret-token-123" not in err

    # fix the fault, retry: succeeds with exactly the source files
    if fault in ("corrupt-shard", "404"):
        api.upload_file(path_or_fileobj=good_shard, path_in_repo=shard, repo_id=REPO, repo_type="dataset")
    elif fault in ("wrong-offset", "inflated-size"):
        api.upload_file(path_or_fileobj=good_table, path_in_repo=table, repo_id=REPO, repo_type="dataset")
    elif fault == "truncated":
        hub_standin.faults.clear()
    else:
        monkeypatch.setenv("HF_TOKEN", "secret-token-123")
        monkeypatch.delenv("HF_HUB_DISABLE_IMPLICIT_TOKEN")
    rc, err = _fault_install(tmp_path, HF, capsys)
    assert rc == 0, err
    assert _data(tmp_path / "install" / "objects" / "objaverse") == \
        read_tree(objects)
    assert ResourceManager(tmp_path / "cache", tmp_path / "install").verify() == []


@pytest.mark.parametrize("fault", ["truncate", "404", "401", "corrupt"])
def test_bucket_faults_are_one_line_and_retry_succeeds(fault, bucket, tmp_path, capsys, read_tree):
    objects = _objects_tree(tmp_path / "src", 4)
    groups = publish_bucket(objects, bucket.root, "objects", "objaverse", "1")
    rel = f"objects/objaverse/1/{sorted(groups)[2]}"
    path = bucket.root / rel
    good = path.read_bytes()
    if fault == "404":
        path.unlink()
    elif fault == "corrupt":
        path.write_bytes(good[:20] + bytes(len(good) - 40) + good[-20:])
    else:
        bucket.faults[rel] = fault
    rc, err = _fault_install(tmp_path, bucket.url, capsys)
    pattern = {"truncate": "transfer of the file failed|truncated response", "404": r"not found \(HTTP 404\)",
               "401": r"denied \(HTTP 401\); the bucket is not public", "corrupt": "cannot be read"}[fault]
    _assert_failed_cleanly(tmp_path, rc, err, pattern)
    bucket.faults.clear()
    path.write_bytes(good)
    rc, err = _fault_install(tmp_path, bucket.url, capsys)
    assert rc == 0, err
    assert _data(tmp_path / "install" / "objects" / "objaverse") == \
        read_tree(objects)


def test_bucket_archive_inflating_past_the_ratio_cap_is_refused_once(bucket, tmp_path, capsys):
    """Their archives carry no checksum or per-file sizes: unpacking stops at 64x the archive's size."""
    tree = tmp_path / "src"
    (tree / "bomb").mkdir(parents=True)
    (tree / "bomb" / "zeros.bin").write_bytes(bytes(32 << 20))
    groups = publish_bucket(tree, bucket.root, "objects", "objaverse", "1")
    rc, err = _fault_install(tmp_path, bucket.url, capsys)
    _assert_failed_cleanly(tmp_path, rc, err, "past its limit of .* bytes")
    assert bucket.archive_gets() == {f"objects/objaverse/1/{next(iter(groups))}": 1}  # no second download
    written = sum(p.stat().st_size for p in (tmp_path / "cache").rglob("*") if p.is_file())
    assert written < 1 << 20


@pytest.mark.parametrize("what, content, match", [
    (ms.REMOTE_MANIFEST, {"objaverse_00aa0bb.tar.zst": "big"}, "sizes in MB"),
    (ms.REMOTE_MANIFEST, ["objaverse_00aa0bb.tar.zst"], "sizes in MB"),
    (ms.TRIES, {"objaverse_00aa0bb.tar.zst": {"a": []}}, "node 'a' is not a JSON object"),
    (ms.TRIES, {"objaverse_00aa0bb.tar.zst": {"..": {"x": {}}}}, "is not a clean relative path"),
    (ms.TRIES, {"objaverse_00aa0bb.tar.zst": {".objaverse_01aa1bb.tar.zst_complete_extract": {}}},
     "keeps for its own bookkeeping"),
])
def test_their_metadata_with_wrong_types_is_one_line(bucket, tmp_path, capsys, what, content, match):
    import gzip

    publish_bucket(_objects_tree(tmp_path / "src", 1), bucket.root, "objects", "objaverse", "1")
    raw = json.dumps(content).encode()
    (bucket.root / "objects" / "objaverse" / "1" / what).write_bytes(gzip.compress(raw) if what == ms.TRIES else raw)
    rc, err = _fault_install(tmp_path, bucket.url, capsys)
    assert rc == 1 and err.count("\n") == 1 and what in err and match in err, err


# -- the preset: MolmoSpaces' version table into their assets dir layout ----------------------------------------
def test_preset_installs_the_pinned_versions_into_the_assets_dir(bucket, tmp_path, monkeypatch, capsys):
    for data_type, sources in ms.VERSIONS.items():
        for source, version in sources.items():
            tree = tmp_path / "trees" / data_type / source
            (tree / "a").mkdir(parents=True)
            (tree / "a" / f"{source}.xml").write_text(f"<mujoco model='{source}'/>\n")
            (tree / "b.txt").write_text(version)
            publish_bucket(tree, bucket.root, data_type, source, version)
    assets, cache = tmp_path / "assets", tmp_path / "mlcache"
    monkeypatch.setenv("MLSPACES_ASSETS_DIR", str(assets))
    monkeypatch.setenv("MLSPACES_CACHE_DIR", str(cache))
    assert main(["install", "--preset", "molmospaces", "--remote", bucket.url, "--no-progress"]) == 0
    out = capsys.readouterr().out
    n = sum(len(s) for s in ms.VERSIONS.values())
    assert out.count("installed ") == n
    assert (assets / "robots" / "franka_droid" / "a" / "franka_droid.xml").is_symlink()  # per file, eager
    assert (assets / "objects" / "thor").is_symlink()
    assert (assets / "objects" / "thor" / "b.txt").read_text() == "20251117"
    assert (assets / "grasps" / "droid" / "a" / "droid.xml").is_file()  # eager
    # scenes: on demand, but (as MolmoSpaces' setup does) small datasets are extracted whole
    assert "scenes/ithor@20251217_with_occupancy (on demand, 2 of its 2 base archives extracted)" in out
    assert (assets / "scenes" / "ithor" / "b.txt").read_text() == "20251217_with_occupancy"
    assert (assets / "scenes" / "ithor" / ms.TRIES).is_file()
    assert "objects/objaverse@20260131 (on demand)" in out  # objaverse: nothing until asked
    assert not (assets / "objects" / "objaverse" / "b.txt").exists()
    linked = json.loads((assets / ms.LOCAL_MANIFEST).read_text())
    assert linked == ms.VERSIONS
    mgr = ResourceManager(cache, assets, bucket.url, progress=False)
    assert mgr.ensure_path("objects/objaverse@20260131", "b.txt").read_text() == "20260131"
    assert (assets / "objects" / "objaverse" / "b.txt").read_text() == "20260131"
    assert mgr.verify() == []

    table = tmp_path / "pins.json"
    table.write_text(json.dumps({"objects": {"thor": "20251117"}}))
    assert main(["install", "--preset", str(table), "--remote", bucket.url, "--no-progress"]) == 0
    assert "objects/thor@20251117 (eager): 0 archives extracted" in capsys.readouterr().out


def test_setup_archives_follow_their_scene_rule():
    small = [f"ithor_{i}.tar.zst" for i in range(4)]
    big = [f"procthor_{i}.tar.zst" for i in range(12)] + ["procthor_base.tar.zst"]
    assert ms.setup_archives("scenes", small) == small
    assert ms.setup_archives("scenes", big) == ["procthor_base.tar.zst"]
    assert ms.setup_archives("objects", small) == []


# -- interop with molmospaces-resources' on-disk layout --------------------------------------------------------
def test_cache_written_in_their_layout_is_adopted_without_the_remote(bucket, tmp_path, read_tree):
    """A cache and install dir as molmospaces-resources leaves them (made by hand here) are used as-is."""
    objects = _objects_tree(tmp_path / "src", 3)
    groups = publish_bucket(objects, bucket.root, "objects", "thor", "20251117")
    src = bucket.root / "objects" / "thor" / "20251117"
    vdir = tmp_path / "cache" / "objects" / "thor" / "20251117"
    vdir.mkdir(parents=True)
    for name in (ms.REMOTE_MANIFEST, ms.TRIES):
        (vdir / name).write_bytes((src / name).read_bytes())
    for archive in groups:
        import zstandard

        with zstandard.ZstdDecompressor().stream_reader(open(src / archive, "rb")) as zr, \
                tarfile.open(fileobj=zr, mode="r|") as tar:
            tar.extractall(vdir, filter="data")
        (vdir / f".{archive}_complete_extract").touch()
    for p in vdir.rglob("*"):
        if p.is_file() and not p.is_symlink() and not p.name.startswith("."):
            p.chmod(0o444)
    (tmp_path / "cache" / ms.LOCAL_MANIFEST).write_text(json.dumps({"objects": {"thor": ["20251117"]}}))
    (tmp_path / "install" / "objects").mkdir(parents=True)
    (tmp_path / "install" / "objects" / "thor").symlink_to(vdir, target_is_directory=True)
    (tmp_path / "install" / ms.LOCAL_MANIFEST).write_text(json.dumps({"objects": {"thor": "20251117"}}))
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", None, progress=False)
    assert mgr.installed() == {"objects": {"thor": ["20251117"]}}
    assert mgr.verify() == []
    assert mgr.is_complete("objects/thor@20251117")
    res = mgr.install("objects/thor@20251117")
    assert (res.extracted, res.present) == (0, len(groups))
    assert mgr.ensure_uid("objects/thor@20251117", "01aa1bb")[0].is_file()
    assert bucket.gets == {}  # nothing asked of any remote


def test_their_lock_left_held_is_one_clear_line_and_no_lock_workers_read(bucket, tmp_path):
    """FAQ 2: a ``.lock`` left held on a shared file system names the file to delete; workers read without locks."""
    from filelock import FileLock

    from molmo_lerobot.resources import ResourceError, StaleLockError

    publish_bucket(_objects_tree(tmp_path / "src", 2), bucket.root, "objects", "thor", "1")
    (tmp_path / "cache").mkdir()
    held = FileLock(str(tmp_path / "cache" / ms.LOCK))
    held.acquire()  # as molmospaces-resources holds it (no owner file), e.g. after a killed container on NFS
    try:
        mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", bucket.url, progress=False, lock_timeout=0.2)
        with pytest.raises(StaleLockError, match=r"waiting for lock .*cache/\.lock held by an unknown process; "
                                                 r"if that process no longer exists, delete .*cache/\.lock and retry"):
            mgr.install("objects/thor@1")
    finally:
        held.release()
    worker = ResourceManager(tmp_path / "cache", tmp_path / "install", bucket.url, progress=False, use_lock=False)
    with pytest.raises(ResourceError, match="no-lock mode never installs"):
        worker.install("objects/thor@1")
    assert not (tmp_path / "cache" / "objects" / "thor" / "1").exists()  # nothing of theirs touched without the lock
    assert ResourceManager(tmp_path / "cache", tmp_path / "install", bucket.url, progress=False).install(
        "objects/thor@1").extracted == 2
    gets = sum(bucket.gets.values())
    res = worker.install("objects/thor@1")
    assert res.present == 2 and (res.path / "01aa1bb" / "01aa1bb.xml").is_file()
    assert sum(bucket.gets.values()) == gets and not list((tmp_path / "cache").glob(".lock.owner"))
