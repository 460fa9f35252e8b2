"""What a developmental program is: an online policy over one world's observations that, now and
then, emits an embedding of what it learned (and events about itself).

A program answers every observation with exactly one Decision, handles one observation at a time,
owns its random generator, and never looks at ground truth (the link scores embeddings). Programs
are deterministic given their seed and the observation stream, so a recording replayed offline
gives the same embeddings.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from sensorimotor.protocol.messages import Observation, WorldSpec
from sensorimotor.protocol.params import parse


@dataclass(frozen=True)
class Decision:
    """The answer to one observation: action values, or a reset to `start` (-1 = random)."""

    values: tuple[float, ...] = ()
    reset: bool = False
    start: int = -1


@dataclass(frozen=True)
class EmbeddingOutput:
    trigger: str
    ids: tuple[int, ...]
    coordinates: np.ndarray
    eigenvalues: tuple[float, ...]
    step: int
    metrics: dict[str, float] = field(default_factory=dict)
    absolute: bool = False  # coordinates are in the truth's own units (E_geometry is meaningful)


@dataclass(frozen=True)
class EventOutput:
    kind: str
    detail: str
    step: int
    values: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class EchoParams:
    """The echo program has no parameters."""


class Program(abc.ABC):
    """A developmental program. It declares its hyperparameters once, as a frozen dataclass (see
    `protocol.params`) named by the class attribute `Params`; its constructor takes
    `(spec, seed, params=None, **overrides)` and keeps the parsed instance as `self.params`."""

    name = "program"
    Params: ClassVar[type] = EchoParams
    # settings for the daemon's drop detector that suit this program's `performance` stream, e.g. a
    # shorter warm-up for one value per episode than for one per step
    detector_params: dict[str, Any] = {}

    def __init__(self, spec: WorldSpec, seed: int = 0) -> None:
        self.spec = spec
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self._outbox: list[Any] = []

    @abc.abstractmethod
    def act(self, obs: Observation) -> Decision:
        """Learn from `obs` and answer it."""

    def drain(self) -> list[Any]:
        """Embeddings and events produced since the last call."""
        out, self._outbox = self._outbox, []
        return out

    def emit(self, item: Any) -> None:
        self._outbox.append(item)

    def world_restarted(self) -> None:
        """The world process restarted (new session): an episode in progress is gone."""

    def performance(self, obs: Observation) -> float | None:
        """The signal the daemon's drop detector watches (None: nothing to report for this step).
        Programs without a meaningful per-step performance return None and are not watched."""
        return None

    def on_drop(self, step: int) -> None:
        """The detector saw a drop in `performance`: relearn as the learner prescribes."""

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_outbox"] = []
        return state


class EchoProgram(Program):
    """Answers every observation with action 0: the baseline for the loop benchmark."""

    name = "echo"
    Params = EchoParams

    def __init__(self, spec: WorldSpec, seed: int = 0, params: EchoParams | None = None, **overrides: Any) -> None:
        super().__init__(spec, seed)
        self.params = parse(EchoParams, overrides, name=self.name, base=params)

    def act(self, obs: Observation) -> Decision:
        return Decision((0.0,))
