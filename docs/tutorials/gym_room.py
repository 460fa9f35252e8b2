"""Your first world, as a Gymnasium environment.

A 7 x 7 room whose observation is an opaque cell number, four moves, reward 1 and the end of the
episode on reaching the centre. It follows the conventions of Gymnasium's toy-text environments
(FrozenLake, CliffWalking): a transition table ``P[s][a] = [(prob, next, reward, terminated)]``,
``nrow``/``ncol`` and the current cell in ``s``. From those, `sme world gym:ENV_ID` finds the start
states (every cell reachable and not terminal) and the truth ((row, col) of each) by itself.

This module registers ``Room-v0`` with Gymnasium when imported; run it to serve the room with
the `sme world` command (its flags pass through, e.g. ``--connect``)::

    python gym_room.py                   # = sme world gym:Room-v0, once the id is registered
    sme watch                            # another shell: embeddings as they arrive
"""

from __future__ import annotations

import sys

import gymnasium as gym
import numpy as np
from gymnasium import spaces

ENV_ID = "Room-v0"
MOVES = ((-1, 0), (1, 0), (0, -1), (0, 1))  # rows: 0 up, 1 down, 2 left, 3 right


class Room(gym.Env):
    """A square room of `size` x `size` cells; the goal is the centre cell."""

    metadata = {"render_modes": []}

    def __init__(self, size: int = 7) -> None:
        self.nrow = self.ncol = size
        self.goal = (size // 2) * size + size // 2
        self.observation_space = spaces.Discrete(size * size)
        self.action_space = spaces.Discrete(4)
        self.P: dict[int, dict[int, list[tuple[float, int, float, bool]]]] = {}
        for s in range(size * size):
            r, c = divmod(s, size)
            self.P[s] = {}
            for a, (dr, dc) in enumerate(MOVES):
                nr, nc = min(max(r + dr, 0), size - 1), min(max(c + dc, 0), size - 1)
                nxt = nr * size + nc
                self.P[s][a] = [(1.0, nxt, float(nxt == self.goal), nxt == self.goal)]
        self.initial_state_distrib = np.full(size * size, 1.0 / (size * size - 1))
        self.initial_state_distrib[self.goal] = 0.0
        self.s = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.s = int(self.np_random.choice(self.nrow * self.ncol, p=self.initial_state_distrib))
        return self.s, {}

    def step(self, action):
        _, self.s, reward, terminated = self.P[self.s][int(action)][0]
        return self.s, reward, terminated, False, {}


gym.register(id=ENV_ID, entry_point=Room, max_episode_steps=50)


def main(argv: list[str]) -> int:
    from sensorimotor.tools.cli import main as sme

    return sme(["world", f"gym:{ENV_ID}", *argv])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
