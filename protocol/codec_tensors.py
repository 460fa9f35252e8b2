"""The codec's limits and its tensors: the size, count and dtype bounds every message is held to,
and named numpy arrays to and from `sme.v1.Tensor`, checked (dtype whitelist, shape against bytes,
size, finite floats) before anything large is allocated; the number checks the codecs share."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sensorimotor.protocol import errors, limits
from sensorimotor.protocol import sme_v1_pb2 as pb

MAX_MESSAGE_BYTES = 64 * 1024 * 1024
MAX_TENSORS = 64
MAX_TENSOR_BYTES = 32 * 1024 * 1024
MAX_DIMS = 8

DTYPES: dict[str, np.dtype] = {
    name: np.dtype(name).newbyteorder("<")
    for name in ("uint8", "int8", "uint16", "int16", "int32", "int64", "float32", "float64", "bool")
}

_DTYPE_NAMES: dict[np.dtype, str] = {}


def dtype_name(dt: np.dtype) -> str:
    """``dt.name``, memoised: numpy computes the name in Python each time (~5 us, on the hot path)."""
    name = _DTYPE_NAMES.get(dt)
    if name is None:
        name = _DTYPE_NAMES[dt] = dt.name
    return name


def _not_nan(value: float, what: str) -> float:
    if math.isnan(value):
        raise errors.NonFiniteValue(f"{what} is NaN; a bound may be infinite, never NaN")
    return value


def _finite(value: float, what: str) -> float:
    if not math.isfinite(value):
        raise errors.NonFiniteValue(f"{what} is {value!r}; only finite numbers are accepted")
    return value


def _limited(value: int, limit: int, what: str) -> int:
    """`value` if its wire field (`protocol.limits`) can carry it; OutOfRange naming the field otherwise."""
    if not limits.within(value, limit):
        raise errors.OutOfRange(f"{what} {value!r} is out of the wire's range 0 .. {limit}")
    return value


def _tensor_to_pb(name: str, array: np.ndarray, out: pb.Tensor) -> None:
    a = np.asarray(array)
    dt = dtype_name(a.dtype)
    if dt not in DTYPES:
        raise errors.BadDtype(f"tensor {name!r}: dtype {dt} is not one of {sorted(DTYPES)}")
    if a.ndim > MAX_DIMS:
        raise errors.ShapeMismatch(f"tensor {name!r}: {a.ndim} dimensions, at most {MAX_DIMS}")
    if a.nbytes > MAX_TENSOR_BYTES:
        raise errors.OversizeMessage(f"tensor {name!r}: {a.nbytes} bytes, at most {MAX_TENSOR_BYTES}")
    out.name = name
    out.dtype = dt
    out.shape.extend(a.shape)
    out.data = np.ascontiguousarray(a, dtype=DTYPES[dt]).tobytes()


def _tensor_from_pb(t: pb.Tensor, where: str) -> np.ndarray:
    name = t.name or "?"
    dt = DTYPES.get(t.dtype)
    if dt is None:
        raise errors.BadDtype(f"{where}: tensor {name!r} has dtype {t.dtype!r}; allowed: {sorted(DTYPES)}")
    shape = tuple(t.shape)
    if len(shape) > MAX_DIMS:
        raise errors.ShapeMismatch(f"{where}: tensor {name!r} has {len(shape)} dimensions, at most {MAX_DIMS}")
    claimed = math.prod(shape) * dt.itemsize  # Python ints: a huge claim cannot overflow
    if claimed > MAX_TENSOR_BYTES:
        raise errors.OversizeMessage(
            f"{where}: tensor {name!r} claims shape {list(shape)} = {claimed} bytes, at most {MAX_TENSOR_BYTES}"
        )
    data = t.data  # each access copies the bytes out of the message
    if claimed != len(data):
        raise errors.ShapeMismatch(
            f"{where}: tensor {name!r} shape {list(shape)} x {dt.name} needs {claimed} bytes, got {len(data)}"
        )
    a = np.frombuffer(data, dtype=dt).reshape(shape)
    if dt.kind == "f" and a.size and not np.isfinite(a).all():
        raise errors.NonFiniteValue(f"{where}: tensor {name!r} contains NaN or inf")
    return a


def _tensors_from_pb(ts: Any, where: str) -> dict[str, np.ndarray]:
    if len(ts) > MAX_TENSORS:
        raise errors.OversizeMessage(f"{where}: {len(ts)} tensors, at most {MAX_TENSORS}")
    out: dict[str, np.ndarray] = {}
    for t in ts:
        if t.name in out:
            raise errors.MalformedMessage(f"{where}: tensor name {t.name!r} appears twice")
        out[t.name] = _tensor_from_pb(t, where)
    return out


def _tensors_to_pb(tensors: dict[str, np.ndarray], field: Any) -> None:
    if len(tensors) > MAX_TENSORS:
        raise errors.OversizeMessage(f"{len(tensors)} tensors, at most {MAX_TENSORS}")
    for name, a in tensors.items():
        _tensor_to_pb(name, a, field.add())
