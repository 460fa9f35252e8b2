"""The wire contract: message schemas, key expressions, validating codec, and the zenoh bus."""

from sensorimotor.protocol import keys
from sensorimotor.protocol.codec import decode, encode, schema_name
from sensorimotor.protocol.errors import (
    BadDtype, MalformedMessage, NonFiniteValue, OversizeMessage, ProtocolError, ShapeMismatch,
    SpecMismatch, UnknownVersion,
)
from sensorimotor.protocol.messages import (
    SCHEMA_VERSION, Action, ActionSpace, AgentEvent, AgentStatus, Control, Embedding, LinkStatus,
    Observation, SensorSpec, Truth, WorldSpec,
)

__all__ = [
    "keys", "decode", "encode", "schema_name", "SCHEMA_VERSION", "Action", "ActionSpace",
    "AgentEvent", "AgentStatus", "Control", "Embedding", "LinkStatus", "Observation", "SensorSpec",
    "Truth", "WorldSpec", "BadDtype", "MalformedMessage", "NonFiniteValue", "OversizeMessage",
    "ProtocolError", "ShapeMismatch", "SpecMismatch", "UnknownVersion",
]
