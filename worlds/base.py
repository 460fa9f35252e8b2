"""The World interface: what every simulator offers, in-process or served over the bus by `node`."""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from sensorimotor.protocol.messages import Control, Truth, WorldSpec


@dataclass(frozen=True)
class StepResult:
    tensors: dict[str, np.ndarray]
    reward: float = 0.0
    done: bool = False
    info: dict[str, Any] = field(default_factory=dict)


class PerturbationError(ValueError):
    """A Control the world cannot apply; the message says why."""


@dataclass(frozen=True)
class NoParams:
    """A world without parameters."""


class World(abc.ABC):
    """A simulator the agent learns from. Worlds own their random generator (`seed=`).

    A world declares its parameters once, as a frozen dataclass (see `protocol.params`) named by the
    class attribute `Params`; its constructor takes `(world_id, seed, params=None, **overrides)` and
    keeps the parsed instance as `self.params`.
    """

    kind: str = "world"
    max_episode_steps: int = 1000
    Params: ClassVar[type] = NoParams
    # the parsed instance of `Params`; Any because a subclass may declare other parameters than its
    # base (MountainCarWorld extends VergenceWorld with its own MountainCarWorldParams)
    params: Any

    def __init__(self, world_id: str = "w0", seed: int = 0) -> None:
        self.world_id = world_id
        self.seed = seed
        self.rng = np.random.default_rng(seed)

    @abc.abstractmethod
    def spec(self) -> WorldSpec: ...

    @abc.abstractmethod
    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Begin an episode from start state `start` (0..n_starts-1) or a random one (None)."""

    @abc.abstractmethod
    def step(self, action: np.ndarray) -> StepResult: ...

    def pick_start(self, seed: int | None, start: int | None, n_starts: int) -> int:
        """For `reset`: reseed if asked, draw a random start state when `start` is None or negative,
        refuse one out of range."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if start is None or start < 0:
            return int(self.rng.integers(n_starts))
        if start >= n_starts:
            raise ValueError(f"start {start} out of range 0..{n_starts - 1}")
        return int(start)

    def perturb(self, control: Control) -> str:
        """Apply a perturbation; return a one-line description of what changed."""
        raise PerturbationError(f"world kind {self.kind!r} has no perturbation {control.kind!r}")

    def truth(self) -> Truth | None:
        """Ground truth for evaluation only (never fed to learners)."""
        return None

    def frame(self) -> np.ndarray | None:
        """The latest camera frame (uint8 [H, W] or [H, W, 3]) for viewers and recordings, if any."""
        return None

    def close(self) -> None:
        pass

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def param(params: Mapping[str, Any], name: str, default: Any, cast: type = str) -> Any:
    """Read one perturbation (`Control`) parameter with a clear error when it does not parse.
    World parameters are declared in the world's `Params` dataclass instead."""
    if name not in params:
        return default
    raw = params[name]
    try:
        if cast is bool and isinstance(raw, str):
            if raw.lower() in ("1", "true", "yes", "on"):
                return True
            if raw.lower() in ("0", "false", "no", "off"):
                return False
            raise ValueError(raw)
        return cast(raw)
    except (TypeError, ValueError):
        raise ValueError(f"parameter {name}={raw!r} is not a valid {cast.__name__}") from None
