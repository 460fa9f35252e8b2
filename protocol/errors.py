"""Typed errors of the wire contract: each says what was wrong with a message."""

from __future__ import annotations


class ProtocolError(ValueError):
    """A message was refused. `kind` is a short stable label used in counters and events."""

    kind = "protocol"


class MalformedMessage(ProtocolError):
    kind = "malformed"


class UnknownVersion(ProtocolError):
    kind = "unknown_version"


class BadDtype(ProtocolError):
    kind = "bad_dtype"


class ShapeMismatch(ProtocolError):
    kind = "shape_mismatch"


class OversizeMessage(ProtocolError):
    kind = "oversize"


class NonFiniteValue(ProtocolError):
    kind = "non_finite"


class SpecMismatch(ProtocolError):
    """Well-formed, but not what the world's spec promised (missing sensor, wrong action size...)."""

    kind = "spec_mismatch"
