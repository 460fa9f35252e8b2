"""The generic body changes' parameter sets: one typed, documented dataclass per kind.

`GENERIC` maps each kind to its declaration; `kinds_for` says which of them a world's action space
can take (every one, for a box of actions and for discrete actions alike).
An ``index`` names a box dimension or a discrete action (``-1``: every one); the world checks it
against its own action space and refuses one out of range with the valid values.
"""

from __future__ import annotations

from dataclasses import dataclass

from sensorimotor.protocol.messages import ActionSpace
from sensorimotor.protocol.params import option

EVERY = -1  # an index meaning "every dimension / every action"


@dataclass(frozen=True)
class ReverseParams:
    """A motor's sign reversed: a box dimension mirrored about the middle of its range (-a for a
    symmetric range), or a discrete action swapped with its opposite (again to undo)."""

    index: int = option(EVERY, "box: the dimension; discrete: the action (with its opposite); -1: every one", min=-1)
    pairs: str = option(
        "auto",
        "discrete: the opposites, 'a:b,c:d' (auto: by the action names - up/down, left/right... - when the world "
        "names them, else the mirrored index i <-> n-1-i)",
    )


@dataclass(frozen=True)
class PermuteParams:
    """Actions (discrete) or action dimensions (box) exchanged: the agent's i acts as the world's order[i]."""

    order: str = option(
        "rotate",
        "rotate (i acts as i+1, the last as the first), 'a:b' (those two exchanged) or a full list '2,0,1'",
    )


@dataclass(frozen=True)
class GainParams:
    """A weaker or stronger motor: a box dimension scaled about the middle of its range (clipped to
    the range); a discrete action applied `gain` times per step (a fractional part: once more with
    that probability, so 0.5 acts every other step on average; 0: not at all)."""

    index: int = option(EVERY, "box: the dimension; discrete: the action; -1: every one", min=-1)
    gain: float = option(2.0, "the factor (box: negative also reverses; discrete: 0..10)", min=-10.0, max=10.0)
    seed: int = option(0, "discrete, fractional gain: seeds which steps act once more", min=0)


@dataclass(frozen=True)
class LesionParams:
    """An action that no longer acts, or a sensor region that reads 0."""

    what: str = option("action", "what is lesioned", choices=("action", "sensor"))
    index: int = option(
        0,
        "what=action: the box dimension (held at the middle of its range) or the discrete action (the body "
        "stays where it is, reward 0); -1: every one",
        min=-1,
    )
    sensor: str = option("", "what=sensor: the sensor (empty: every sensor)")
    start: float = option(
        0.0, "what=sensor: where the region begins, a fraction of the flattened sensor", min=0.0, max=1.0
    )
    stop: float = option(0.5, "what=sensor: where the region ends (a fraction, above start)", min=0.0, max=1.0)


@dataclass(frozen=True)
class NoiseParams:
    """Gaussian sensor noise, in the sensor's own units (integer sensors rounded; clipped to finite
    declared bounds), seeded."""

    sd: float = option(0.05, "standard deviation, in the sensor's units", min=0.0, max=1e6)
    sensor: str = option("", "the sensor (empty: every sensor)")
    seed: int = option(0, "seeds the noise (the same seed, the same noise)", min=0)


@dataclass(frozen=True)
class DelayParams:
    """Actions applied k steps late: each step applies the action of k steps before (the first k
    steps of an episode rest: a box at the middle of its range, a discrete body stays where it is)."""

    steps: int = option(1, "k, the delay in steps", min=1, max=1000)


@dataclass(frozen=True)
class RestoreParams:
    """Back to the body as it was: every generic change undone (and the world's own `heal`, if it has one)."""


GENERIC: dict[str, type] = {
    "reverse": ReverseParams,
    "permute": PermuteParams,
    "gain": GainParams,
    "lesion": LesionParams,
    "noise": NoiseParams,
    "delay": DelayParams,
    "restore": RestoreParams,
}


def kinds_for(space: ActionSpace) -> dict[str, type]:
    """The generic kinds a world with action space `space` can take: every one (each says what it
    does to a box of actions and to discrete ones)."""
    return dict(GENERIC)
