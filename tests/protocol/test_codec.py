"""The msgpack + numpy codec: openpi's exact wire format, refusals, read-only decoding."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from molmo_lerobot.protocol.codec import CodecError, packb, unpackb


@pytest.mark.parametrize("dtype", ["uint8", "int16", "int64", "float16", "float32", ">f8", "bool"])
def test_array_roundtrip_keeps_dtype_shape_and_is_read_only(dtype):
    a = (np.arange(24) % 3).astype(dtype).reshape(2, 3, 4)
    b = unpackb(packb({"x": a}))["x"]
    assert b.dtype == a.dtype and b.shape == a.shape and np.array_equal(a, b)
    assert not b.flags.writeable
    with pytest.raises(ValueError):
        b[0, 0, 0] = 1


def test_wire_format_is_openpis():
    a = np.arange(6, dtype=np.float32).reshape(2, 3)[:, ::2]  # non-contiguous view
    raw = msgpack.unpackb(packb({"a": a, "s": np.int32(7)}), raw=False)
    assert raw["a"] == {b"__ndarray__": True, b"data": np.ascontiguousarray(a).tobytes(), b"dtype": "<f4",
                        b"shape": [2, 2]}
    assert raw["s"] == {b"__npgeneric__": True, b"data": 7, b"dtype": "<i4"}


def test_decodes_openpi_style_bytes_keys_and_str_keys():
    data = np.array([1.5, 2.5], dtype="<f8").tobytes()
    for keys in ((b"__ndarray__", b"data", b"dtype", b"shape"), ("__ndarray__", "data", "dtype", "shape")):
        msg = msgpack.packb({"x": dict(zip(keys, (True, data, "<f8", [2]), strict=True))}, use_bin_type=True)
        np.testing.assert_array_equal(unpackb(msg)["x"], [1.5, 2.5])
    scalar = unpackb(packb(np.float32(0.25)))
    assert isinstance(scalar, np.float32) and scalar == 0.25


@pytest.mark.parametrize("value", [
    np.zeros(2, np.complex64), np.array([object()]), np.zeros(2, "V4"), np.complex128(1j), np.array(["ab"], "T"),
    np.array(["ab"]), np.array([b"ab"]), np.zeros(2, "M8[s]"), np.zeros(2, np.longdouble),
])
def test_encodes_only_bool_int_and_float_dtypes(value):
    with pytest.raises(CodecError, match="refusing"):
        packb({"x": value})


def test_refuses_bad_messages_on_decode():
    def ext(**fields):
        return msgpack.packb({b"__ndarray__": True, **{k.encode(): v for k, v in fields.items()}}, use_bin_type=True)

    with pytest.raises(CodecError, match="refusing dtype"):
        unpackb(ext(data=b"\0" * 8, dtype="<c8", shape=[1]))
    with pytest.raises(CodecError, match="refusing dtype"):
        unpackb(ext(data=b"\0" * 8, dtype="|O", shape=[1]))
    with pytest.raises(CodecError, match="refusing dtype 'f4,i4'"):
        unpackb(ext(data=b"\0" * 8, dtype="f4,i4", shape=[1]))
    with pytest.raises(CodecError, match="needs 16 bytes, got 8"):
        unpackb(ext(data=b"\0" * 8, dtype="<f8", shape=[2]))
    with pytest.raises(CodecError, match="lacks field 'shape'"):
        unpackb(ext(data=b"", dtype="<f8"))
    with pytest.raises(CodecError, match="malformed msgpack"):
        unpackb(b"\xc1\xff\x00 definitely not msgpack")
    with pytest.raises(CodecError):
        unpackb(packb({"a": 1}) + b"trailing")


@pytest.mark.parametrize("dtype", ["T", "|T16", "<U2", "|S8", "<M8[s]", "<m8", "<f16", "|V8", "float32", 7])
def test_decodes_only_whitelisted_dtypes(dtype):
    """numpy 2's StringDType ('T') holds pointers: decoding one from wire bytes and printing it crashed CPython."""
    for key in (b"__ndarray__", b"__npgeneric__"):
        msg = msgpack.packb({key: True, b"data": b"\x41" * 16, b"dtype": dtype, b"shape": [1]}, use_bin_type=True)
        with pytest.raises(CodecError, match="dtype"):
            unpackb(msg)


def test_never_pickles_arbitrary_objects():
    class Thing:
        pass

    with pytest.raises(CodecError, match="cannot encode Thing"):
        packb({"x": Thing()})
