"""A Gymnasium environment that offers a body change of its own: the `sme_perturb` hook.

A 5 x 5 room (the tutorial room, smaller): the observation is an opaque cell number, four moves,
reward 1 and the end of the episode at the centre. Its own change, ``mirror``, reverses the moves
along the rows, the columns or both - as a motor wired the wrong way round would. It is offered to
`sme perturb` by two attributes, with no change to sensorimotor itself:

* ``sme_perturbations``: each kind the environment offers, mapped to a parameter dataclass (the
  values are parsed and checked against its declaration before the hook is called, and a bad one
  is refused naming the valid range) or to a one-line description (the hook then gets the
  parameters as strings and checks them itself);
* ``sme_perturb(kind, params) -> str``: apply the change and say what changed; raise ValueError to
  refuse it.

Its kinds are listed beside the generic ones (`sme perturb --list --world MirrorRoom-v0`) and take
precedence over a generic kind of the same name. Serve it from your own package, e.g. ``my_envs/``::

    sme world gym:my_envs.mirror_room:MirrorRoom-v0      # imports the module, which registers the id
    sme perturb mirror --world MirrorRoom-v0             # later: the agent notices, and relearns
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sensorimotor.protocol.params import option

ENV_ID = "MirrorRoom-v0"
MOVES = ((-1, 0), (1, 0), (0, -1), (0, 1))  # rows: 0 up, 1 down, 2 left, 3 right


@dataclass(frozen=True)
class Mirror:
    """Reverse the moves along the rows, the columns or both (sent again: as they were)."""

    axis: str = option("both", "which moves are reversed", choices=("rows", "cols", "both"))


class MirrorRoom(gym.Env):
    """A square room of `size` x `size` cells; the goal is the centre cell; `mirror` reverses moves."""

    metadata = {"render_modes": []}
    sme_perturbations = {"mirror": Mirror}

    def __init__(self, size: int = 5) -> None:
        self.nrow = self.ncol = size
        self.goal = (size // 2) * size + size // 2
        self.observation_space = spaces.Discrete(size * size)
        self.action_space = spaces.Discrete(4)
        self.sign = np.ones(2, dtype=int)  # per axis (rows, cols): 1 as built, -1 reversed
        self.initial_state_distrib = np.full(size * size, 1.0 / (size * size - 1))
        self.initial_state_distrib[self.goal] = 0.0
        # the toy-text convention that lets `sme world gym:` find start states and truth by itself
        self.P = {s: {a: [(1.0, self._next(s, a), 0.0, False)] for a in range(4)} for s in range(size * size)}
        self.s = 0

    def _next(self, s: int, a: int) -> int:
        r, c = divmod(s, self.ncol)
        dr, dc = MOVES[a]
        r = min(max(r + self.sign[0] * dr, 0), self.nrow - 1)
        c = min(max(c + self.sign[1] * dc, 0), self.ncol - 1)
        return r * self.ncol + c

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.s = int(self.np_random.choice(self.nrow * self.ncol, p=self.initial_state_distrib))
        return self.s, {}

    def step(self, action):
        self.s = self._next(self.s, int(action))
        at_goal = self.s == self.goal
        return self.s, float(at_goal), at_goal, False, {}

    def sme_perturb(self, kind: str, params: Mirror) -> str:
        """The hook: `kind` is one of `sme_perturbations`, `params` its checked dataclass."""
        if params.axis in ("rows", "both"):
            self.sign[0] *= -1
        if params.axis in ("cols", "both"):
            self.sign[1] *= -1
        return f"moves along rows {'reversed' if self.sign[0] < 0 else 'as built'}, " + (
            f"along columns {'reversed' if self.sign[1] < 0 else 'as built'}"
        )


gym.register(id=ENV_ID, entry_point=MirrorRoom, max_episode_steps=30)
