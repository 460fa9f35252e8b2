"""The wire contract: message schemas, key expressions, validating codec, and the zenoh bus."""

from sensorimotor.protocol import keys
from sensorimotor.protocol.codec import decode, encode, schema_name
from sensorimotor.protocol.errors import (
    BadDtype,
    MalformedMessage,
    NonFiniteValue,
    OversizeMessage,
    ProtocolError,
    ShapeMismatch,
    SpecMismatch,
    UnknownVersion,
)
from sensorimotor.protocol.messages import (
    SCHEMA_VERSION,
    Action,
    ActionSpace,
    AgentEvent,
    AgentStatus,
    AttachConfig,
    Control,
    Embedding,
    EventKind,
    LinkStatus,
    Observation,
    SensorSpec,
    Trigger,
    Truth,
    WorldEvent,
    WorldEventKind,
    WorldSpec,
)

__all__ = [
    "keys", "decode", "encode", "schema_name", "SCHEMA_VERSION", "Action", "ActionSpace",
    "AgentEvent", "AgentStatus", "AttachConfig", "Control", "Embedding", "EventKind", "LinkStatus", "Observation",
    "SensorSpec", "Trigger", "Truth", "WorldEvent", "WorldEventKind", "WorldSpec", "BadDtype", "MalformedMessage", "NonFiniteValue", "OversizeMessage",
    "ProtocolError", "ShapeMismatch", "SpecMismatch", "UnknownVersion",
]
