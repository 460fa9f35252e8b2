"""The 33-byte attachment rmw_zenoh (since PR #601: Jazzy >= 0.2.4, Humble >= 0.1.2, Rolling >= 0.6)
puts on every sample: int64 sequence number, int64 source timestamp (ns), a length byte 16, the
16-byte GID of the publisher, little-endian (what ``zenoh.ext.z_serialize((Int64, Int64, bytes))``
writes). rmw_zenoh subscribers drop a sample without it; so do we (`parse` raises).

An entity's GID is the XXH3-128 hash of its liveliness token, low 64 bits first, each half
little-endian (rmw_zenoh `liveliness_utils.cpp`)."""

from __future__ import annotations

import struct
from dataclasses import dataclass

import xxhash

SIZE = 33
GID_SIZE = 16
_FORMAT = struct.Struct("<qqB16s")


class AttachmentError(ValueError):
    """A sample whose attachment is missing or not rmw_zenoh's 33 bytes."""


@dataclass(frozen=True)
class Attachment:
    """What a sample's attachment says: its publisher's sequence number, source time and GID."""

    sequence: int
    timestamp_ns: int
    gid: bytes

    def encode(self) -> bytes:
        """The 33 bytes."""
        if len(self.gid) != GID_SIZE:
            raise AttachmentError(f"a GID has {GID_SIZE} bytes, not {len(self.gid)}")
        return _FORMAT.pack(self.sequence, self.timestamp_ns, GID_SIZE, self.gid)


def parse(raw: bytes | None) -> Attachment:
    """The attachment of a sample; an AttachmentError for none or a malformed one."""
    if raw is None:
        raise AttachmentError("sample without attachment (rmw_zenoh drops these)")
    if len(raw) != SIZE:
        raise AttachmentError(f"attachment of {len(raw)} bytes, rmw_zenoh's has {SIZE}")
    seq, ts, n, gid = _FORMAT.unpack(raw)
    if n != GID_SIZE:
        raise AttachmentError(f"attachment GID length byte {n}, expected {GID_SIZE}")
    return Attachment(seq, ts, gid)


def gid_of(token: str) -> bytes:
    """The GID of the entity whose liveliness token is `token`."""
    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(GID_SIZE, "little")
