"""Several installer processes at once, and an installer killed with SIGKILL half way."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time

from molmo_lerobot.resources import ResourceManager, pack

CLI = [sys.executable, "-m", "molmo_lerobot.cli.resources"]


def _install_cmd(tmp_path, *extra):
    return [*CLI, "install", "objects/big@1", "--remote", str(tmp_path / "remote"), "--cache-dir",
            str(tmp_path / "cache"), "--install-dir", str(tmp_path / "install"), "--no-progress", *extra]


def test_four_processes_install_same_version_once(src_tree, tmp_path, read_tree):
    for i in range(12):
        (src_tree / f"obj_{i:02d}").mkdir()
        (src_tree / f"obj_{i:02d}" / "data.bin").write_bytes(os.urandom(20_000))
    manifest = pack(src_tree, tmp_path / "remote", "objects/big@1", link="file", max_archive_bytes=30_000)
    n = len(manifest["archives"])
    assert n >= 8
    t0 = time.perf_counter()
    procs = [subprocess.Popen(_install_cmd(tmp_path, "--workers", "2"), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(4)]
    outs = [p.communicate(timeout=120) for p in procs]
    elapsed = time.perf_counter() - t0
    assert [p.returncode for p in procs] == [0] * 4, [o[1] for o in outs]
    extracted = [int(re.search(r"(\d+) archives extracted", o[0]).group(1)) for o in outs]
    assert sum(extracted) == n and sorted(extracted)[:3] == [0, 0, 0], extracted  # the work happened once
    install = tmp_path / "install" / "objects" / "big"
    assert read_tree(install) == read_tree(src_tree)  # exactly the source tree, through version-free paths
    vdir = tmp_path / "cache" / "objects" / "big" / "1"
    regular = [p for p in vdir.rglob("*") if p.is_file() and not p.is_symlink()]
    assert regular and all(p.stat().st_mode & 0o222 == 0 for p in regular)
    assert ResourceManager(tmp_path / "cache", tmp_path / "install").verify() == []
    print(f"4 concurrent installs of {n} archives: {elapsed:.2f} s")


def test_kill_9_during_install_then_reinstall_is_complete(src_tree, tmp_path):
    for i in range(40):
        (src_tree / f"obj_{i:02d}").mkdir()
        (src_tree / f"obj_{i:02d}" / "data.bin").write_bytes(os.urandom(200_000))
    manifest = pack(src_tree, tmp_path / "remote", "objects/big@1", max_archive_bytes=150_000)
    n = len(manifest["archives"])
    done = tmp_path / "cache" / ".molmo" / "objects" / "big" / "1" / "done"
    proc = subprocess.Popen(_install_cmd(tmp_path, "--workers", "1"), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (done.is_dir() and any(done.glob("*.ok"))):
        time.sleep(0.002)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    finished = len(list(done.glob("*.ok")))
    assert 0 < finished < n, f"kill landed outside the install ({finished}/{n} archives done)"
    mgr = ResourceManager(tmp_path / "cache", tmp_path / "install", tmp_path / "remote", progress=False)
    assert not mgr.is_complete("objects/big@1")  # nothing looks complete
    res = mgr.install("objects/big@1")
    assert res.extracted == n - finished and res.present == finished
    assert mgr.is_complete("objects/big@1") and mgr.verify() == []
    assert not any((tmp_path / "cache" / ".molmo" / "objects" / "big" / "1" / "tmp").iterdir())



def test_each_thread_decodes_the_index_with_its_own_zstd_context():
    """python-zstandard's contexts must never be used by two threads at once; concurrent installs
    decoded index entries through one shared context and the process died (segmentation fault)."""
    from molmo_lerobot.resources.index import _get_codec

    seen = []
    threads = [threading.Thread(target=lambda: seen.append(_get_codec())) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len({id(codec) for codec in seen}) == 4 and _get_codec() not in seen
    raw = _get_codec().encode({"files": {"a/b.bin": [1, "x"]}})
    assert all(codec.decode(raw) == {"files": {"a/b.bin": [1, "x"]}} for codec in seen)
