"""Typed errors of the wire contract: each says what was wrong with a message."""

from __future__ import annotations


class ProtocolError(ValueError):
    """A message was refused. `kind` is a short stable label used in counters and events."""

    kind = "protocol"


class MalformedMessage(ProtocolError):
    """The bytes are not a protobuf message of the expected type (or a tensor name repeats)."""

    kind = "malformed"


class UnknownVersion(ProtocolError):
    """The message's schema version is not the one this build speaks."""

    kind = "unknown_version"


class BadDtype(ProtocolError):
    """A tensor's dtype is not on the whitelist (`codec.DTYPES`)."""

    kind = "bad_dtype"


class ShapeMismatch(ProtocolError):
    """A tensor's shape disagrees with its bytes, or has too many dimensions."""

    kind = "shape_mismatch"


class OversizeMessage(ProtocolError):
    """A message, a tensor, or a tensor's claimed shape is over the size limits."""

    kind = "oversize"


class NonFiniteValue(ProtocolError):
    """NaN or inf in a reward, an action value or a float tensor."""

    kind = "non_finite"


class OutOfRange(ProtocolError):
    """A number beyond its wire field's range (`protocol.limits`: a uint32 embedding version...)."""

    kind = "out_of_range"


class SpecMismatch(ProtocolError):
    """Well-formed, but not what the world's spec promised (missing sensor, wrong action size...)."""

    kind = "spec_mismatch"
