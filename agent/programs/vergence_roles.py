"""Which of the body's actions verge the eyes: a probe the mountain-car program runs after every drop,
before it relearns vergence (`permute`, `reverse`: the actions it converged and diverged with may
now drive the car, and others verge).

Why a probe, and why this one: the program reads the car's place from how far it converges its eyes
(ch. 8), counting its own converge and diverge commands. A body whose actions were exchanged leaves
no vergence policy over the old two, or one whose count of converging steps means nothing. What tells
the actions apart is what each does to the view from a start with the eyes parallel: converging
turns the eyes (a large change of the view), diverging from there turns them back (the very view
again, and again: it stays parallel), and a drive moves the car and sets the eyes parallel (a view
that drifts as the car goes on). So for every ordered pair of actions (c, b), from one start (a
fixed state where the car moves): the view after c, then after b sent `repeats` times; the pair
whose second action undoes the largest share of the first one's change of the view - all of it,
for (converge, diverge) alone - is (converge, diverge). The other actions drive, in their order
(the driver relearns which is which). 2 + `repeats` steps a pair: 100 for 5 actions.
When no pair undoes its change whole (`UNDONE`), or more than one does, nothing verges as it did
(a lesioned converge) and the probe names no roles. An episode that ends or restarts within a pair
has that pair run again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sensorimotor.agent.programs.base import Decision
from sensorimotor.protocol.messages import Observation

#: the share of its first action's change of the view a (converge, diverge) pair undoes at least
UNDONE = 0.95


def view(obs: Observation) -> np.ndarray:
    """Every sensor of `obs`, flattened into one float vector."""
    return np.concatenate([np.asarray(obs.tensors[k], dtype=np.float64).reshape(-1) for k in sorted(obs.tensors)])


@dataclass
class VergenceRoleProbe:
    """Finds the (converge, diverge) pair among `n_actions` by the views each ordered pair gives
    from start `start` (see the module). Online: `begin()`, then `step(obs)` until it returns None;
    `roles()` is then the physical action of each role: converge, diverge, then the drives."""

    n_actions: int = 5
    repeats: int = 3
    start: int = -1
    _pairs: list[tuple[int, int]] = field(default_factory=list)
    _i: int = 0
    _stage: int = 0
    _base: np.ndarray | None = None
    _after: np.ndarray | None = None
    _scores: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.n_actions < 2 or self.repeats < 1:
            raise ValueError("a vergence role probe needs at least 2 actions and 1 repeat")
        self._pairs = [(c, b) for c in range(self.n_actions) for b in range(self.n_actions) if c != b]

    @property
    def finished(self) -> bool:
        return self._i >= len(self._pairs)

    def begin(self) -> Decision:
        """The first step: a start, eyes parallel."""
        self._i, self._stage, self._scores = 0, 0, []
        return Decision(reset=True, start=self.start)

    def step(self, obs: Observation) -> Decision | None:
        """Observe the result of the last decision; the next decision, or None when every pair is seen."""
        if self.finished:
            return None
        if self._stage < 0 or (self._stage >= 1 and (obs.done or obs.t == 0)):
            return self._again()  # restarted, or the episode ended within the pair
        c, b = self._pairs[self._i]
        v = view(obs)
        if self._stage == 0:
            self._base, self._stage = v, 1
            return Decision((float(c),))
        if self._stage == 1:
            self._after = v
        if self._stage <= self.repeats:
            self._stage += 1
            return Decision((float(b),))
        assert self._base is not None and self._after is not None
        away = float(np.abs(self._after - self._base).mean())
        back = float(np.abs(v - self._base).mean())
        # the share of c's change that b undid (1 for converge, diverge only; at least -1); -2: c
        # changed nothing (diverging with the eyes parallel)
        self._scores.append(max(1.0 - back / away, -1.0) if away > 1e-12 else -2.0)
        self._i, self._stage = self._i + 1, 0
        return None if self.finished else Decision(reset=True, start=self.start)

    def interrupted(self) -> None:
        """The world restarted: the pair in progress is run again from its start."""
        self._stage = -1

    def _again(self) -> Decision:
        self._stage = 0
        return Decision(reset=True, start=self.start)

    def roles(self) -> tuple[int, ...] | None:
        """The physical action of each role (converge, diverge, then the others in order), or None
        when no single pair undid its change whole (nothing verges as it did)."""
        if not self.finished:
            raise RuntimeError("the vergence role probe has not seen every pair yet")
        scores = np.asarray(self._scores)
        if int((scores >= UNDONE).sum()) != 1:
            return None
        c, b = self._pairs[int(np.argmax(scores))]
        return (c, b, *[a for a in range(self.n_actions) if a not in (c, b)])

    def state(self) -> dict[str, Any]:
        return {
            "start": self.start,
            "i": self._i,
            "stage": self._stage,
            "base": None if self._base is None else self._base.copy(),
            "after": None if self._after is None else self._after.copy(),
            "scores": list(self._scores),
        }

    def restore(self, state: dict[str, Any]) -> None:
        i, stage, scores = int(state["i"]), int(state["stage"]), [float(s) for s in state["scores"]]
        if not (0 <= i <= len(self._pairs) and -1 <= stage <= self.repeats + 1 and len(scores) == i):
            raise ValueError("vergence role probe state out of range")
        if (stage >= 1 and state["base"] is None) or (stage >= 2 and state["after"] is None):
            raise ValueError("vergence role probe state lacks the views its stage needs")
        self._i, self._stage, self._scores = i, stage, scores
        self._base = None if state["base"] is None else np.asarray(state["base"], dtype=np.float64)
        self._after = None if state["after"] is None else np.asarray(state["after"], dtype=np.float64)


__all__ = ["VergenceRoleProbe", "view"]
