"""Resource manager: install modes, links, upgrades, verification, locks, no-lock mode, fork safety."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time

import pytest
from filelock import FileLock

from molmo_lerobot.resources import ResourceError, ResourceManager, StaleLockError, pack


def _mgr(tmp_path, **kw):
    kw.setdefault("progress", False)
    return ResourceManager(tmp_path / "cache", tmp_path / "install", tmp_path / "remote", **kw)


@pytest.mark.parametrize("link", ["dir", "file"])
def test_eager_install_links_exact_tree_read_only(src_tree, tmp_path, read_tree, link):
    manifest = pack(src_tree, tmp_path / "remote", "objects/lib@1", link=link, max_archive_bytes=2500)
    assert len(manifest["archives"]) == 3  # one UID never spans archives
    mgr = _mgr(tmp_path)
    res = mgr.install("objects/lib@1")
    assert (res.extracted, res.present) == (3, 0)
    assert res.path == tmp_path / "install" / "objects" / "lib"
    assert read_tree(res.path) == read_tree(src_tree)
    assert res.path.is_symlink() == (link == "dir")
    for p in mgr.version_dir("objects/lib@1").rglob("*"):
        if p.is_file() and not p.is_symlink():
            assert p.stat().st_mode & 0o222 == 0, p
    assert mgr.verify() == []
    assert mgr.installed() == {"objects": {"lib": ["1"]}}
    assert mgr.linked() == {"objects": {"lib": "1"}}
    again = mgr.install("objects/lib@1")
    assert (again.extracted, again.present) == (0, 3)


@pytest.mark.parametrize("link", ["dir", "file"])
def test_upgrade_repoints_links(src_tree, tmp_path, read_tree, link):
    pack(src_tree, tmp_path / "remote", "objects/lib@1", link=link)
    (src_tree / "README.txt").write_text("version two\n")
    (src_tree / "pear_03").mkdir()
    (src_tree / "pear_03" / "pear_03.xml").write_text("<mujoco/>")
    pack(src_tree, tmp_path / "remote", "objects/lib@2", link=link)
    mgr = _mgr(tmp_path)
    mgr.install("objects/lib@1")
    path = mgr.install("objects/lib@2").path
    assert read_tree(path) == read_tree(src_tree)
    assert mgr.linked() == {"objects": {"lib": "2"}}
    assert mgr.installed() == {"objects": {"lib": ["1", "2"]}}
    assert (mgr.version_dir("objects/lib@1") / "README.txt").read_text() == "top level\n"  # old version intact
    assert mgr.verify() == []


def test_on_demand_installs_archives_on_first_use(src_tree, tmp_path):
    pack(src_tree, tmp_path / "remote", "objects/lib@1", link="file", max_archive_bytes=2500)
    hooks = []
    mgr = _mgr(tmp_path, post_setup=[lambda m, spec, path: hooks.append((str(spec), path))])
    res = mgr.install("objects/lib@1", on_demand=True)
    assert res.extracted == 0 and not mgr.is_complete("objects/lib@1")
    assert hooks == [("objects/lib@1", res.path)]
    assert not (res.path / "mug_02" / "mug_02.xml").exists()
    files = mgr.ensure_uid("objects/lib@1", "mug_02")
    assert sorted(p.name for p in files) == ["handle.bin", "mug_02.xml", "same.xml"]
    assert (res.path / "mug_02" / "same.xml").read_text() == "<mujoco model='mug'/>\n"  # link added in place
    assert not (res.path / "apple_01").exists()
    p = mgr.ensure_path("objects/lib@1", "apple_01/apple_01.xml")
    assert p.read_text() == "<mujoco model='apple'/>\n"
    mgr.ensure_path("objects/lib@1", "README.txt")
    assert mgr.is_complete("objects/lib@1")
    with pytest.raises(ResourceError, match=r"no archive holds 'nope.txt'"):
        mgr.ensure_path("objects/lib@1", "nope.txt")
    assert mgr.verify() == []


def test_no_lock_mode_reads_but_never_writes(src_tree, tmp_path):
    pack(src_tree, tmp_path / "remote", "objects/lib@1")
    worker = _mgr(tmp_path, use_lock=False)
    with pytest.raises(ResourceError, match="a leader must install it first"):
        worker.install("objects/lib@1")
    assert not (tmp_path / "cache").exists()
    _mgr(tmp_path).install("objects/lib@1", on_demand=True)
    with pytest.raises(ResourceError, match="no-lock mode never installs"):
        worker.ensure_uid("objects/lib@1", "apple_01")
    _mgr(tmp_path).install("objects/lib@1")
    res = worker.install("objects/lib@1")
    assert res.extracted == 0 and (res.path / "README.txt").read_text() == "top level\n"
    assert worker.index("objects/lib@1").archives_for_uid("apple_01")
    assert not list((tmp_path / "cache" / ".molmo" / "locks").glob("*.owner"))


def test_verify_reports_tampering(src_tree, tmp_path):
    pack(src_tree, tmp_path / "remote", "objects/lib@1")
    mgr = _mgr(tmp_path)
    mgr.install("objects/lib@1")
    target = mgr.version_dir("objects/lib@1") / "apple_01" / "mesh.bin"
    os.chmod(target, 0o644)
    target.write_bytes(b"tampered")
    (mgr.version_dir("objects/lib@1") / "README.txt").unlink()
    problems = mgr.verify()
    assert any("apple_01/mesh.bin" in p and "differs" in p for p in problems)
    assert any("README.txt" in p and "missing" in p for p in problems)


def test_overlapping_dirs_and_bad_specs_are_refused(tmp_path):
    with pytest.raises(ResourceError, match="must not overlap"):
        ResourceManager(tmp_path / "c", tmp_path / "c" / "inst")
    with pytest.raises(ResourceError, match="expected DATA_TYPE/SOURCE@VERSION"):
        ResourceManager(tmp_path / "c", tmp_path / "i").install("objects-lib-1")
    with pytest.raises(ResourceError, match=r"no objects/lib@9 .versions there: none"):
        _mgr(tmp_path).install("objects/lib@9")


def test_missing_version_lists_available(src_tree, tmp_path):
    pack(src_tree, tmp_path / "remote", "objects/lib@1")
    with pytest.raises(ResourceError, match=r"has no objects/lib@2 \(versions there: 1\)"):
        _mgr(tmp_path).install("objects/lib@2")


def test_versions_are_immutable_on_remote(src_tree, tmp_path):
    pack(src_tree, tmp_path / "remote", "objects/lib@1")
    with pytest.raises(ResourceError, match="already exists"):
        pack(src_tree, tmp_path / "remote", "objects/lib@1")


def test_stale_lock_is_reported_with_what_to_do(src_tree, tmp_path):
    pack(src_tree, tmp_path / "remote", "objects/lib@1")
    lock_path = tmp_path / "cache" / ".molmo" / "locks" / "objects+lib+1.lock"
    lock_path.parent.mkdir(parents=True)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    held = FileLock(str(lock_path))
    held.acquire()  # a lock that stays held (as on NFS after a killed container)
    try:
        owner = {"pid": int(dead.stdout), "host": socket.gethostname(), "since": time.time()}
        (tmp_path / "cache" / ".molmo" / "locks" / "objects+lib+1.lock.owner").write_text(json.dumps(owner))
        with pytest.raises(StaleLockError, match=r"stale lock .*pid \d+\) is gone.*delete .*objects\+lib\+1\.lock"):
            _mgr(tmp_path, lock_timeout=0.2).install("objects/lib@1")
    finally:
        held.release()
    assert _mgr(tmp_path).install("objects/lib@1").extracted == 1


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_index_handles_are_reset_after_fork(src_tree, tmp_path):
    pack(src_tree, tmp_path / "remote", "objects/lib@1", max_archive_bytes=2500)
    mgr = _mgr(tmp_path)
    mgr.install("objects/lib@1")
    parent_answer = mgr.index("objects/lib@1").archives_for_uid("mug_02")
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: must reopen LMDB, not reuse the parent's handle
        try:
            idx = mgr.index("objects/lib@1")
            ok = idx.archives_for_uid("mug_02") == parent_answer and idx._pid == os.getpid()
            os.write(w, b"1" if ok else b"0")
        finally:
            os._exit(0)
    os.close(w)
    _, status = os.waitpid(pid, 0)
    assert os.read(r, 1) == b"1" and status == 0
    assert mgr.index("objects/lib@1").archives_for_uid("mug_02") == parent_answer
