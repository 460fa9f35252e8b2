"""The wire's numeric limits, declared once: the codec checks what it encodes against them and
every boundary where a value enters the agent (checkpoint restore, shared checkpoints, the bus)
refuses a value beyond them, so a value that cannot be sent is never held.

The limits follow the field types of `schemas/sme_v1.proto` (uint32 and uint64 fields).
"""

from __future__ import annotations

UINT32_MAX = 2**32 - 1
UINT64_MAX = 2**64 - 1

#: Embedding.version and LinkStatus.embedding_version are uint32 fields
EMBEDDING_VERSION_MAX = UINT32_MAX
#: Observation.step, Action.step, LinkStatus.steps and the other step and count fields are uint64
STEP_MAX = UINT64_MAX
#: lease epochs (Action.epoch, Lease.epoch, Checkpoint.epoch) are uint64
EPOCH_MAX = UINT64_MAX


def within(value: int, limit: int) -> bool:
    """True when `value` is an int (not a bool) in 0 .. `limit`."""
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= limit


def check(value: int, limit: int, what: str) -> int:
    """`value` when it is an int in 0 .. `limit` (a wire field can carry it); ValueError naming
    `what` and the range otherwise."""
    if not within(value, limit):
        raise ValueError(f"{what} {value!r} is out of the wire's range 0 .. {limit}")
    return value
