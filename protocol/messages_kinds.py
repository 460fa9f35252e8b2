"""What the messages share: the schema version, the echo limit (`clip`), the program name of an
externally driven world, and the enumerations carried as one token on the wire."""

from __future__ import annotations

from enum import StrEnum

SCHEMA_VERSION = 1
MAX_ECHO = 1000  # characters of its input an event's detail or a log line copies at most (see `clip`)


def clip(text: str, limit: int = MAX_ECHO) -> str:
    """`text` cut to `limit` characters with a note of how much was left out: events and log lines
    say what input they refused without copying all of it (1 MB in must not make a 1 MB event)."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... [{len(text) - limit} more characters not shown]"


#: `WorldSpec.program` of a world driven by an outside controller (`sme world --external`, a
#: Gymnasium `BusEnv`): agents do not attach to it
EXTERNAL_PROGRAM = "external"


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
    LEASE_LOST = "lease_lost"  # the world applies another owner's actions now: this agent stopped answering it
    LEASE_REFUSED = "lease_refused"  # the world's lease is held by another owner; this agent waits (`reason`: held)


class Trigger(StrEnum):
    """Why an Embedding version was made (its `trigger`)."""

    RANDOM_POLICY = "random_policy"
    POLICY_ITERATION = "policy_iteration"  # `iteration` says which
    PERIODIC = "periodic"
    RELEARNED = "relearned"  # after a detected drop, at `drop_step`
    POLICY_MAP = "policy_map"  # clustered traces of a trained policy (ch. 9.6), `labels` per row


class GoalRule(StrEnum):
    """How a world's goal is recognised (`WorldSpec.goal`): what ends a trace as a success."""

    REWARD = "reward"  # a positive reward (the dissertation's worlds)
    TERMINATED = "terminated"  # the episode ended on a terminal state, not by a time limit (Gymnasium)
    SUCCESS = "success"  # the observation's success flag (panda-gym's, Gymnasium-Robotics' is_success)
    NONE = "none"  # no goal state (CartPole, Pendulum: their terminations are failures or never come)


class WorldEventKind(StrEnum):
    """The `kind` of a WorldEvent."""

    ACTION_REFUSED = "action_refused"  # the world could not apply an action; it reset the episode instead
    CONTROL_APPLIED = "control_applied"
    CONTROL_REFUSED = "control_refused"
    LEASE_LOST = "lease_lost"  # an action whose owner/epoch is not the current lease was not applied
