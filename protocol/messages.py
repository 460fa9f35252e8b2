"""The messages as plain frozen dataclasses: what agent and worlds work with (never protobuf).

One module per side, all importable from here: `messages_kinds` (schema version, `clip`, the
enumerations), `messages_world` (spec, observation, action, control, truth, world event),
`messages_agent` (embedding, agent event, status) and `messages_owners` (leases, shared checkpoints).
"""

from __future__ import annotations

from sensorimotor.protocol.messages_agent import (
    AgentEvent,
    AgentStatus,
    AttachConfig,
    Embedding,
    EmbeddingScores,
    LinkStatus,
)
from sensorimotor.protocol.messages_kinds import (
    EXTERNAL_PROGRAM,
    MAX_ECHO,
    SCHEMA_VERSION,
    EventKind,
    GoalRule,
    Trigger,
    WorldEventKind,
    clip,
)
from sensorimotor.protocol.messages_owners import Lease, LeaseRequest, SharedCheckpoint
from sensorimotor.protocol.messages_world import (
    Action,
    ActionSpace,
    Control,
    Observation,
    SensorSpec,
    Truth,
    WorldEvent,
    WorldSpec,
)

__all__ = [
    "EXTERNAL_PROGRAM",
    "MAX_ECHO",
    "SCHEMA_VERSION",
    "Action",
    "ActionSpace",
    "AgentEvent",
    "AgentStatus",
    "AttachConfig",
    "Control",
    "Embedding",
    "EmbeddingScores",
    "EventKind",
    "GoalRule",
    "Lease",
    "LeaseRequest",
    "LinkStatus",
    "Observation",
    "SensorSpec",
    "SharedCheckpoint",
    "Trigger",
    "Truth",
    "WorldEvent",
    "WorldEventKind",
    "WorldSpec",
    "clip",
]
