"""MolmoSpaces' metadata LMDB holds zstd pickles: numpy data loads (any protocol), nothing else does."""

from __future__ import annotations

import pickle

import lmdb
import numpy as np
import pytest
import zstandard

from molmo_lerobot.assets import AssetError
from molmo_lerobot.molmospaces.libraries import LMDB_COMPLETE_KEY, ObjathorMetadata


class _Exec:
    def __reduce__(self):
        return (exec, ("raise SystemExit('ran')",))


ENTRIES = {
    # pickle.dumps(np.array(...), protocol=5) goes through numpy's _frombuffer
    "p5": pickle.dumps({"clip": np.full((3, 4), 0.5, np.float16), "n": np.int64(3)}, protocol=5),
    "p4": pickle.dumps({"clip": np.full((3, 4), 0.5, np.float16)}, protocol=4),
    "exec": pickle.dumps(_Exec(), protocol=5),
    # allowed callables with bad arguments: numpy raises TypeError, OrderedDict too
    "bad_dtype": b"\x80\x02cnumpy\ndtype\nX\x02\x00\x00\x00xx\x85R.",
    "bad_call": b"\x80\x02ccollections\nOrderedDict\nK\x01K\x02\x86R.",
    "out_of_band": pickle.dumps(pickle.PickleBuffer(np.arange(3)), protocol=5, buffer_callback=lambda b: False),
    "truncated": pickle.dumps({"a": 1}, protocol=5)[:-4],
}


@pytest.fixture
def metadata(tmp_path):
    path = tmp_path / ".lmdb" / "objathor_metadata" / "20250101"
    path.mkdir(parents=True)
    env = lmdb.open(str(path), map_size=1 << 22)
    with env.begin(write=True) as txn:
        for key, raw in ENTRIES.items():
            txn.put(key.encode(), zstandard.compress(raw))
        txn.put(LMDB_COMPLETE_KEY.encode(), zstandard.compress(pickle.dumps(LMDB_COMPLETE_KEY)))
    env.close()
    return ObjathorMetadata(tmp_path)


def test_numpy_arrays_load_from_protocol_4_and_5(metadata):
    for key in ("p5", "p4"):
        doc = metadata.get(key)
        assert doc["clip"].dtype == np.float16 and doc["clip"].shape == (3, 4) and float(doc["clip"][0, 0]) == 0.5
    assert metadata.get("p5")["n"] == 3


@pytest.mark.parametrize(("key", "reason"), [
    ("exec", "refusing to load builtins.exec"),
    ("bad_dtype", "TypeError: data type 'xx' not understood"),
    ("bad_call", "TypeError: "),
    ("out_of_band", "out-of-band"),
    ("truncated", "truncated"),
])
def test_everything_else_is_refused_with_one_line(metadata, key, reason):
    with pytest.raises(AssetError) as info:
        metadata.get(key)
    text = str(info.value)
    assert f"entry {key!r} unreadable" in text and reason in text and "\n" not in text
