"""msgpack with numpy arrays, byte-compatible with openpi's ``msgpack_numpy``.

Arrays travel as ``{b"__ndarray__": True, b"data": <bytes>, b"dtype": dtype.str, b"shape": [...]}``
and numpy scalars as ``{b"__npgeneric__": True, b"data": item, b"dtype": dtype.str}``. Only the
bool, integer and float dtypes of :data:`ALLOWED_DTYPES` (either byte order) are encoded or decoded:
a received dtype string is looked up, never parsed by numpy, so string, object, void, datetime and
complex arrays (whose raw bytes can hold pointers) never reach a policy or a worker. Nothing is
ever pickled. Decoded arrays are read-only views on the received bytes.
"""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np

from molmo_lerobot.errors import MolmoError

ALLOWED_DTYPES = tuple(np.dtype(t) for t in (
    np.bool_, np.int8, np.int16, np.int32, np.int64, np.uint8, np.uint16, np.uint32, np.uint64,
    np.float16, np.float32, np.float64,
))
_BY_NAME = {d.str: d for dt in ALLOWED_DTYPES for d in (dt.newbyteorder("<"), dt.newbyteorder(">"))}
_ALLOWED_TEXT = "bool, int8-64, uint8-64, float16/32/64"
_ARRAY, _GENERIC = "__ndarray__", "__npgeneric__"


class CodecError(MolmoError, ValueError):
    """A value cannot be encoded, or a received message is not a valid protocol message."""


def allowed_dtype(name: Any) -> np.dtype:
    """The dtype ``name`` (a ``dtype.str`` or a dtype) if in :data:`ALLOWED_DTYPES`, else :class:`CodecError`."""
    if isinstance(name, np.dtype):
        name = name.str
    if isinstance(name, bytes):
        name = name.decode("ascii", "replace")
    if not isinstance(name, str):
        raise CodecError(f"dtype must be a string, got {type(name).__name__}")
    dtype = _BY_NAME.get(name)
    if dtype is None:
        raise CodecError(f"refusing dtype {name[:40]!r} (allowed: {_ALLOWED_TEXT})")
    return dtype


def _encode(obj: Any) -> Any:
    if isinstance(obj, (np.ndarray, np.generic)) and obj.dtype.str not in _BY_NAME:
        raise CodecError(f"refusing to encode dtype {obj.dtype} (allowed: {_ALLOWED_TEXT})")
    if isinstance(obj, np.ndarray):
        return {b"__ndarray__": True, b"data": obj.tobytes(), b"dtype": obj.dtype.str, b"shape": list(obj.shape)}
    if isinstance(obj, np.generic):
        return {b"__npgeneric__": True, b"data": obj.item(), b"dtype": obj.dtype.str}
    raise CodecError(f"cannot encode {type(obj).__name__} (allowed: msgpack types, numpy arrays and scalars)")


def _field(obj: dict, name: str) -> Any:
    for key in (name.encode(), name):
        if key in obj:
            return obj[key]
    raise CodecError(f"numpy extension map lacks field {name!r}")


def _decode(obj: dict) -> Any:
    if obj.get(b"__ndarray__", obj.get(_ARRAY)) is True:
        dtype = allowed_dtype(_field(obj, "dtype"))
        data, shape = _field(obj, "data"), _field(obj, "shape")
        if not isinstance(data, bytes):
            raise CodecError(f"array data must be bytes, got {type(data).__name__}")
        if not isinstance(shape, (list, tuple)) or not all(isinstance(s, int) and s >= 0 for s in shape):
            raise CodecError(f"array shape must be a list of non-negative ints, got {shape!r}")
        expected = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if expected != len(data):
            raise CodecError(f"array of shape {list(shape)} and dtype {dtype} needs {expected} bytes, got {len(data)}")
        return np.ndarray(buffer=data, dtype=dtype, shape=tuple(shape))  # bytes buffer: read-only
    if obj.get(b"__npgeneric__", obj.get(_GENERIC)) is True:
        dtype = allowed_dtype(_field(obj, "dtype"))
        try:
            return dtype.type(_field(obj, "data"))
        except (TypeError, ValueError, OverflowError) as exc:
            raise CodecError(f"bad numpy scalar of dtype {dtype}: {exc}") from exc
    return obj


def packb(obj: Any) -> bytes:
    """Encode ``obj`` (dicts, lists, str, numbers, bytes, numpy arrays and scalars)."""
    try:
        return msgpack.packb(obj, default=_encode, use_bin_type=True)
    except CodecError:
        raise
    except (TypeError, ValueError, OverflowError) as exc:
        raise CodecError(f"cannot encode message: {exc}") from exc


def unpackb(data: bytes) -> Any:
    """Decode one message; any malformation raises :class:`CodecError`."""
    try:
        return msgpack.unpackb(data, object_hook=_decode, raw=False, strict_map_key=False)
    except CodecError:
        raise
    except (ValueError, TypeError, msgpack.UnpackException, msgpack.ExtraData) as exc:
        raise CodecError(f"malformed msgpack message: {type(exc).__name__}: {exc}") from exc
