"""The world side of the lockstep protocol, in one place: observation k, the action that answers
k, observation k+1. `WorldNode` drives it over the bus and `run_inprocess` drives it in-process,
so both number steps, episodes and start states the same way and treat a bad action the same way.
"""

from __future__ import annotations

import time

import numpy as np

from sensorimotor.protocol.messages import Action, Observation, WorldEvent, WorldEventKind
from sensorimotor.worlds.base import StepResult, World


class Lockstep:
    """Step a World by the actions that answer its observations.

    An action the world cannot apply (its `step` or `reset` raises ValueError: a wrong index, a
    start state out of range) is refused: the world starts a new episode from a random start
    instead, so the next observation has a new step and the agent is not asked the same question
    again and again; `advance` returns a `WorldEvent` that says what was refused.

    Parameters
    ----------
    world : World
        The simulator.
    world_id : str
        The id observations carry.
    session : str
        The world process's session (a new value tells the agent the world restarted).

    Examples
    --------
    >>> from sensorimotor.protocol.messages import Action
    >>> from sensorimotor.worlds.gridworld import GridWorld
    >>> lock = Lockstep(GridWorld("grid0"), "grid0")
    >>> obs = lock.observation()
    >>> lock.advance(Action("grid0", obs.step, (0.0,))) is None
    True
    >>> lock.step
    1
    """

    def __init__(self, world: World, world_id: str, session: str = "") -> None:
        self.world = world
        self.world_id = world_id
        self.session = session
        self.step = 0
        self.episode = 0
        self.t = 0
        self.start = -1
        self.result: StepResult = world.reset(start=None)

    def observation(self, timestamp: float = 0.0) -> Observation:
        """The observation of the current step.

        Parameters
        ----------
        timestamp : float, default=0.0
            Seconds since the epoch to stamp it with.

        Returns
        -------
        Observation
        """
        r = self.result
        return Observation(
            self.world_id,
            self.episode,
            self.step,
            self.t,
            r.tensors,
            float(r.reward),
            bool(r.done),
            self.start,
            timestamp,
            self.session,
            bool(r.truncated),
            bool(r.success),
        )

    def _reset(self, start: int) -> None:
        self.start = start
        self.result = self.world.reset(start=None if start < 0 else start)
        self.episode += 1
        self.t = 0

    def advance(self, action: Action) -> WorldEvent | None:
        """Apply the action that answers the current step and move to the next step.

        Parameters
        ----------
        action : Action
            The answer to the current step (a reset when the episode is done or it asks for one).

        Returns
        -------
        WorldEvent or None
            What was refused, when the world could not apply the action (a new episode from a
            random start was begun instead); None otherwise.
        """
        refused: WorldEvent | None = None
        try:
            if self.result.done or action.reset:
                self._reset(action.start if action.start >= 0 else -1)
            else:
                self.result = self.world.step(np.asarray(action.values, dtype=np.float64))
                self.t += 1
        except ValueError as e:
            what = "reset" if self.result.done or action.reset else "action"
            refused = WorldEvent(
                self.world_id,
                WorldEventKind.ACTION_REFUSED,
                f"bad_{what}",
                f"step {action.step}: {e}; a new episode starts instead",
                action.step,
                self.session,
                time.time(),
            )
            self._reset(-1)
        self.step += 1
        return refused
