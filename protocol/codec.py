"""Validating codec between the dataclasses in `messages` and Protocol Buffers bytes.

Every decode checks, before anything large is allocated: total size, schema version, tensor count,
dtype whitelist, shape/bytes agreement, per-tensor size, and finiteness of rewards and float
tensors. Each failure raises a typed `ProtocolError` whose message says what was wrong.

The tensors and limits are in `protocol.codec_tensors`, the per-message encoders and decoders in
`protocol.codec_encode` and `protocol.codec_decode`; this module maps message classes to them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from google.protobuf.message import DecodeError

from sensorimotor.protocol import errors
from sensorimotor.protocol import messages as m
from sensorimotor.protocol import sme_v1_pb2 as pb
from sensorimotor.protocol.codec_decode import (
    _dec_act,
    _dec_checkpoint,
    _dec_ctl,
    _dec_emb,
    _dec_event,
    _dec_lease,
    _dec_lease_request,
    _dec_obs,
    _dec_spec,
    _dec_status,
    _dec_truth,
    _dec_world_event,
)
from sensorimotor.protocol.codec_encode import (
    _enc_act,
    _enc_checkpoint,
    _enc_ctl,
    _enc_emb,
    _enc_event,
    _enc_lease,
    _enc_lease_request,
    _enc_obs,
    _enc_spec,
    _enc_status,
    _enc_truth,
    _enc_world_event,
)
from sensorimotor.protocol.codec_tensors import (
    DTYPES,
    MAX_DIMS,
    MAX_MESSAGE_BYTES,
    MAX_TENSOR_BYTES,
    MAX_TENSORS,
    dtype_name,
)

__all__ = [
    "DTYPES",
    "MAX_DIMS",
    "MAX_MESSAGE_BYTES",
    "MAX_TENSORS",
    "MAX_TENSOR_BYTES",
    "SCHEMA_NAMES",
    "decode",
    "descriptor_set",
    "dtype_name",
    "encode",
    "oversize_field",
    "schema_name",
]

SCHEMA_NAMES = {
    m.WorldSpec: "sme.v1.WorldSpec",
    m.Observation: "sme.v1.Observation",
    m.Action: "sme.v1.Action",
    m.Control: "sme.v1.Control",
    m.Truth: "sme.v1.Truth",
    m.Embedding: "sme.v1.Embedding",
    m.AgentEvent: "sme.v1.AgentEvent",
    m.WorldEvent: "sme.v1.WorldEvent",
    m.AgentStatus: "sme.v1.AgentStatus",
    m.LeaseRequest: "sme.v1.LeaseRequest",
    m.Lease: "sme.v1.Lease",
    m.SharedCheckpoint: "sme.v1.Checkpoint",
}


_CODECS: dict[type, tuple[type, Callable[[Any], Any], Callable[[Any], Any]]] = {
    m.WorldSpec: (pb.WorldSpec, _enc_spec, _dec_spec),
    m.Observation: (pb.Observation, _enc_obs, _dec_obs),
    m.Action: (pb.Action, _enc_act, _dec_act),
    m.Control: (pb.Control, _enc_ctl, _dec_ctl),
    m.Truth: (pb.Truth, _enc_truth, _dec_truth),
    m.Embedding: (pb.Embedding, _enc_emb, _dec_emb),
    m.AgentEvent: (pb.AgentEvent, _enc_event, _dec_event),
    m.WorldEvent: (pb.WorldEvent, _enc_world_event, _dec_world_event),
    m.AgentStatus: (pb.AgentStatus, _enc_status, _dec_status),
    m.LeaseRequest: (pb.LeaseRequest, _enc_lease_request, _dec_lease_request),
    m.Lease: (pb.Lease, _enc_lease, _dec_lease),
    m.SharedCheckpoint: (pb.Checkpoint, _enc_checkpoint, _dec_checkpoint),
}


def encode(msg: Any) -> bytes:
    """Serialise one of the message dataclasses to Protocol Buffers bytes.

    The message is validated like a decode would be (dtypes, shapes, sizes, finite numbers), so
    a bad message fails at the sender, with the sender's stack trace.

    Parameters
    ----------
    msg : WorldSpec, Observation, Action, Control, Truth, Embedding, AgentEvent, WorldEvent or AgentStatus
        The message (an instance of one of the `messages` dataclasses).

    Returns
    -------
    bytes
        The serialized ``sme.v1`` message.

    Raises
    ------
    TypeError
        If `msg` is not a protocol message.
    ProtocolError
        If the message breaks the contract (`BadDtype`, `ShapeMismatch`, `OversizeMessage`,
        `NonFiniteValue`, ...).

    Examples
    --------
    >>> from sensorimotor.protocol import codec, messages
    >>> data = codec.encode(messages.Action("grid0", step=3, values=(1.0,)))
    >>> codec.decode(messages.Action, data).step
    3
    """
    try:
        _, enc, _ = _CODECS[type(msg)]
    except KeyError:
        raise TypeError(f"not a protocol message: {type(msg).__name__}") from None
    try:
        data = enc(msg).SerializeToString()
    except errors.ProtocolError:
        raise
    except ValueError as e:  # protobuf's "Value out of range: N" for an integer beyond its field
        raise errors.OutOfRange(f"{type(msg).__name__}: {e} (see protocol.limits)") from None
    if len(data) > MAX_MESSAGE_BYTES:
        raise errors.OversizeMessage(f"{type(msg).__name__}: {len(data)} bytes, at most {MAX_MESSAGE_BYTES}")
    return data


_FIELD_SLACK = 64 * 1024  # a tensor's name, dtype and shape beside its at most MAX_TENSOR_BYTES of data
_SCAN_FIELDS = 256  # top-level fields looked at before parsing (beyond: the parser decides)


def _varint(data: bytes | bytearray | memoryview, i: int) -> tuple[int, int] | None:
    """The protobuf varint at `i` and the index after it (None: truncated or over 10 bytes)."""
    value = shift = 0
    for j in range(i, min(i + 10, len(data))):
        b = data[j]
        value |= (b & 0x7F) << shift
        if b < 0x80:
            return value, j + 1
        shift += 7
    return None


def oversize_field(data: bytes | bytearray | memoryview) -> int:
    """The length of the first top-level field of `data` (a serialized message) longer than any
    field of an sme message can be (MAX_TENSOR_BYTES plus a tensor's header), 0 if none is among
    the first fields. Read from the wire format without parsing, so that a 33 MiB tensor is refused
    without being copied into a message first (~55 ms of a bus thread per message otherwise)."""
    i, n = 0, len(data)
    for _ in range(_SCAN_FIELDS):
        if i >= n:
            return 0
        key = _varint(data, i)
        if key is None:
            return 0
        wire, i = key[0] & 7, key[1]
        if wire == 0:
            v = _varint(data, i)
            if v is None:
                return 0
            i = v[1]
        elif wire == 1:
            i += 8
        elif wire == 5:
            i += 4
        elif wire == 2:
            ln = _varint(data, i)
            if ln is None:
                return 0
            if ln[0] > MAX_TENSOR_BYTES + _FIELD_SLACK:
                return ln[0]
            i = ln[1] + ln[0]
        else:  # groups or garbage: the parser says what is wrong
            return 0
    return 0


def decode(cls: type, payload: bytes | bytearray | memoryview) -> Any:
    """Parse and validate bytes as message class `cls`.

    Every check (total size, schema version, tensor count, dtype, shape against bytes, finite
    numbers) runs before anything large is allocated, so hostile bytes cannot exhaust memory.

    Parameters
    ----------
    cls : type
        The expected message class (one of the `messages` dataclasses).
    payload : bytes, bytearray or memoryview
        The serialized message, as received.

    Returns
    -------
    object
        An instance of `cls`.

    Raises
    ------
    KeyError
        If `cls` is not a protocol message class.
    ProtocolError
        If the bytes are not a valid `cls` message (`MalformedMessage`, `UnknownVersion`,
        `OversizeMessage`, `BadDtype`, `ShapeMismatch`, `NonFiniteValue`).
    """
    pbcls, _, dec = _CODECS[cls]
    name = cls.__name__
    if len(payload) > MAX_MESSAGE_BYTES:
        raise errors.OversizeMessage(f"{name}: {len(payload)} bytes, at most {MAX_MESSAGE_BYTES}")
    if len(payload) > MAX_TENSOR_BYTES:  # only a message this large can hold a field over the limit
        big = oversize_field(payload)
        if big:
            raise errors.OversizeMessage(
                f"{name}: a field of {big} bytes, at most {MAX_TENSOR_BYTES} per tensor (refused before parsing)"
            )
    p = pbcls()
    try:
        p.ParseFromString(bytes(payload))
    except (DecodeError, RuntimeError, ValueError) as e:
        raise errors.MalformedMessage(f"{name}: not a valid protobuf message ({e})") from None
    if p.schema_version != m.SCHEMA_VERSION:
        raise errors.UnknownVersion(
            f"{name}: schema version {p.schema_version}, this build speaks version {m.SCHEMA_VERSION}"
            + (" (0 usually means the bytes are not an sme message)" if p.schema_version == 0 else "")
        )
    return dec(p)


def schema_name(cls: type) -> str:
    """The protobuf full name of message class `cls` (e.g. ``sme.v1.Observation``), as bus
    encodings and MCAP schemas carry it."""
    return SCHEMA_NAMES[cls]


def descriptor_set(full_name: str) -> bytes:
    """The serialized FileDescriptorSet (with dependencies) defining message `full_name`, as MCAP
    protobuf schema records need. Knows sme.v1.* and foxglove.RawImage."""
    from google.protobuf import descriptor_pb2, descriptor_pool

    from sensorimotor.protocol import images  # noqa: F401  (registers foxglove.RawImage in the default pool)

    try:
        desc = descriptor_pool.Default().FindMessageTypeByName(full_name)
    except KeyError:
        raise KeyError(f"unknown protobuf message {full_name!r}") from None
    fds = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(fd) -> None:
        if fd.name in seen:
            return
        seen.add(fd.name)
        for dep in fd.dependencies:
            add(dep)
        fd.CopyToProto(fds.file.add())

    add(desc.file)
    return fds.SerializeToString()
