"""The messages as plain frozen dataclasses: what agent and worlds work with (never protobuf)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

SCHEMA_VERSION = 1


class EventKind(StrEnum):
    """The `kind` of an AgentEvent (one token on the wire; see protocol/README.md)."""

    ATTACHED = "attached"  # a link to a world was made; `config` says how
    ATTACH_FAILED = "attach_failed"  # `reason`: no_spec, bad_spec, no_program, bad_checkpoint, ...
    PAUSED = "paused"  # `reason`: world_gone, program_errors
    RESUMED = "resumed"
    BAD_INPUT = "bad_input"  # `reason`: the rejection kind (malformed, non_finite, ...)
    DROP_DETECTED = "drop_detected"  # `reason`: the detector's name
    RELEARNING = "relearning"
    RELEARNED = "relearned"
    PROGRAM_ERROR = "program_error"  # `reason`: the exception's type name
    PROGRAM_FALLBACK = "program_fallback"  # the world asked for a program the agent lacks (`reason`)
    POLICY_ITERATION = "policy_iteration"
    EVALUATION = "evaluation"
    WORLD_EVENT = "world_event"  # a WorldEvent the agent saw, `reason` = its kind


class Trigger(StrEnum):
    """Why an Embedding version was made (its `trigger`)."""

    RANDOM_POLICY = "random_policy"
    POLICY_ITERATION = "policy_iteration"  # `iteration` says which
    PERIODIC = "periodic"
    RELEARNED = "relearned"  # after a detected drop, at `drop_step`


class WorldEventKind(StrEnum):
    """The `kind` of a WorldEvent."""

    ACTION_REFUSED = "action_refused"  # the world could not apply an action; it reset the episode instead
    CONTROL_APPLIED = "control_applied"
    CONTROL_REFUSED = "control_refused"


@dataclass(frozen=True)
class SensorSpec:
    name: str
    dtype: str
    shape: tuple[int, ...]
    low: float = 0.0
    high: float = 1.0
    description: str = ""


@dataclass(frozen=True)
class ActionSpace:
    """Discrete (n > 0) or box (low/high per dimension)."""

    n: int = 0
    low: tuple[float, ...] = ()
    high: tuple[float, ...] = ()
    names: tuple[str, ...] = ()

    @property
    def discrete(self) -> bool:
        return self.n > 0

    @property
    def dims(self) -> int:
        return 1 if self.discrete else len(self.low)


@dataclass(frozen=True)
class WorldSpec:
    world_id: str
    kind: str
    sensors: tuple[SensorSpec, ...]
    action_space: ActionSpace
    reward_min: float = 0.0
    reward_max: float = 1.0
    program: str = ""
    n_starts: int = 0
    params: dict[str, str] = field(default_factory=dict)
    session: str = ""

    def sensor(self, name: str) -> SensorSpec:
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(f"world {self.world_id!r} has no sensor {name!r}")


@dataclass(frozen=True)
class Observation:
    world_id: str
    episode: int
    step: int
    t: int
    tensors: dict[str, np.ndarray]
    reward: float = 0.0
    done: bool = False
    start: int = -1
    timestamp: float = 0.0
    session: str = ""


@dataclass(frozen=True)
class Action:
    world_id: str
    step: int
    values: tuple[float, ...] = ()
    reset: bool = False
    start: int = -1
    timestamp: float = 0.0


@dataclass(frozen=True)
class Control:
    world_id: str
    kind: str
    params: dict[str, str] = field(default_factory=dict)
    id: int = 0
    timestamp: float = 0.0


@dataclass(frozen=True)
class Truth:
    world_id: str
    kind: str
    tensors: dict[str, np.ndarray]
    step: int = 0
    timestamp: float = 0.0


@dataclass(frozen=True)
class Embedding:
    agent_id: str
    world_id: str
    version: int
    trigger: str
    ids: tuple[int, ...]
    coordinates: np.ndarray
    eigenvalues: tuple[float, ...]
    procrustes_error: float | None = None
    step: int = 0
    timestamp: float = 0.0
    metrics: dict[str, float] = field(default_factory=dict)
    iteration: int = 0
    drop_step: int | None = None


@dataclass(frozen=True)
class AttachConfig:
    """What decides an agent's behaviour on one world besides its observations."""

    seed: int = 0
    detector: str = ""
    program: str = ""
    program_params: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class AgentEvent:
    agent_id: str
    world_id: str
    kind: str
    detail: str = ""
    step: int = 0
    timestamp: float = 0.0
    values: dict[str, float] = field(default_factory=dict)
    reason: str = ""
    config: AttachConfig | None = None


@dataclass(frozen=True)
class WorldEvent:
    """Something a world reports about itself (e.g. an action it could not apply)."""

    world_id: str
    kind: str
    reason: str = ""
    detail: str = ""
    step: int = 0
    session: str = ""
    timestamp: float = 0.0


@dataclass(frozen=True)
class LinkStatus:
    world_id: str
    kind: str
    program: str
    state: str
    steps: int = 0
    episodes: int = 0
    embedding_version: int = 0
    reward_mean: float = 0.0
    rejected: dict[str, int] = field(default_factory=dict)
    last_procrustes_error: float = float("nan")
    detector_statistic: float = 0.0
    drops: int = 0
    dropped: int = 0


@dataclass(frozen=True)
class AgentStatus:
    agent_id: str
    uptime: float
    links: tuple[LinkStatus, ...] = ()
    counters: dict[str, int] = field(default_factory=dict)
    timestamp: float = 0.0
