"""UID and path lookup in the LMDB index among >= 100,000 indexed paths (target: < 1 ms each)."""

from __future__ import annotations

import random
import statistics
import time

import pytest

from molmo_lerobot.resources.index import PathIndex

N_ARCHIVES, UIDS_PER_ARCHIVE, FILES_PER_UID = 200, 250, 2  # 100,000 paths, 50,000 UIDs


@pytest.mark.perf
def test_uid_lookup_under_1ms_among_100k_paths(tmp_path):
    entries = {
        f"lib-1-{a:05d}.tar.zst": {
            f"obj_{a:03d}_{u:03d}/{name}": [1234, "0" * 64]
            for u in range(UIDS_PER_ARCHIVE)
            for name in ("model.xml", "mesh.obj")[:FILES_PER_UID]
        }
        for a in range(N_ARCHIVES)
    }
    n_paths = sum(len(v) for v in entries.values())
    assert n_paths >= 100_000
    t0 = time.perf_counter()
    PathIndex.build(tmp_path / "index.lmdb", entries)
    build_s = time.perf_counter() - t0

    index = PathIndex(tmp_path / "index.lmdb")
    rng = random.Random(0)
    uids = [(a, u) for a, u in ((rng.randrange(N_ARCHIVES), rng.randrange(UIDS_PER_ARCHIVE)) for _ in range(5000))]
    assert index.archives_for_uid("obj_000_000") == ["lib-1-00000.tar.zst"]  # warm the handle
    uid_times, path_times = [], []
    for a, u in uids:
        t = time.perf_counter()
        got = index.archives_for_uid(f"obj_{a:03d}_{u:03d}")
        uid_times.append(time.perf_counter() - t)
        assert got == [f"lib-1-{a:05d}.tar.zst"]
        t = time.perf_counter()
        got = index.archive_for_path(f"obj_{a:03d}_{u:03d}/model.xml")
        path_times.append(time.perf_counter() - t)
        assert got == f"lib-1-{a:05d}.tar.zst"
    t = time.perf_counter()
    assert index.archives_for_uid("no_such_uid") == []
    miss = time.perf_counter() - t

    def fmt(ts):
        q = statistics.quantiles(ts, n=100)
        return f"mean {statistics.mean(ts) * 1e6:.1f} µs, p50 {q[49] * 1e6:.1f} µs, p99 {q[98] * 1e6:.1f} µs"

    print(f"\nindex of {n_paths} paths / {N_ARCHIVES * UIDS_PER_ARCHIVE} UIDs built in {build_s:.2f} s")
    print(f"UID lookup:  {fmt(uid_times)}")
    print(f"path lookup: {fmt(path_times)}; miss {miss * 1e6:.1f} µs")
