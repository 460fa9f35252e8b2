"""The interface of a table learner: the part of the generic program that learns a policy over
a table of states (state ids, or distinct observations), behind which the program keeps what is
the method's own - sweeps from the start states, trace distances, MDS, which policy's map is
published, watching and relearning.

A learner acts and learns one transition at a time on the act path; its slow work (a plan, a
policy iteration) is a pure module-level function (`plan_job`) of a snapshot (`job_args`), run off
the act path and swapped in with `install` (`agent.programs.background`), so a seeded run is
repeatable whatever the machine's load. Its learned state is explicit arrays and values
(`state`/`restore`), never a pickle. `agent.learners.tabular_model.TabularModel` is the one here;
a package of one's own offers others through the ``sensorimotor.learners`` entry-point group
(`agent.learners.registry`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class TableLearner(Protocol):
    """A policy learner over `n_states` x `n_actions` (built as ``Cls(n_states, n_actions, seed=...)``).

    `q` holds the greedy values the program's sweeps follow (the largest is the action taken; near
    ties are broken toward the previous action). `learn_one` takes the outcome of the step:
    ``continue`` (the episode goes on, or a time limit cut it: `s_next` is where it is), ``goal`` or
    ``failure`` (a termination that is not the goal, worth as little as never arriving)."""

    plan_job: ClassVar[Callable[..., dict[str, Any]]]
    q: np.ndarray

    def act(self, s: int) -> int:
        """An exploring action in state `s`."""
        ...

    def learn_one(self, s: int, a: int, s_next: int | None, outcome: str) -> bool:
        """Learn from one transition; True when a new plan would now differ."""
        ...

    def job_args(self) -> dict[str, Any]:
        """The keyword arguments of `plan_job`: copies, a snapshot of what was learned."""
        ...

    def install(self, result: dict[str, Any]) -> None:
        """Swap in what `plan_job` returned (it updates `q`)."""
        ...

    def complete(self) -> bool:
        """Whether exploring is done (then a plan whose greedy policy changed is worth a sweep)."""
        ...

    def set_stochastic(self, stochastic: bool) -> None:
        """The world was seen to be stochastic (or deterministic again)."""
        ...

    def reset(self) -> None:
        """Forget everything learned (the body changed)."""
        ...

    def state(self) -> dict[str, Any]: ...

    def restore(self, state: dict[str, Any]) -> None: ...


__all__ = ["TableLearner"]
