"""Gridworld (ch. 5, Fig 5.1): a 9x9 grid, goal in the centre, reward 1 on entering the goal.

The agent sees only an opaque state id (cells are numbered in a shuffled order), never the cell
coordinates; those are the ground truth its embedding is scored against. The `barrier` variant
places a wall that divides most of the grid (Fig 5.1b). Moves into walls or off the grid stay put.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from sensorimotor.protocol.messages import ActionSpace, SensorSpec, Truth, WorldSpec
from sensorimotor.worlds.base import StepResult, World, param

MOVES4 = ((0, 1), (0, -1), (-1, 0), (1, 0))
NAMES4 = ("up", "down", "left", "right")
MOVES8 = MOVES4 + ((1, 1), (-1, 1), (1, -1), (-1, -1))
NAMES8 = NAMES4 + ("up-right", "up-left", "down-right", "down-left")


def barrier_cells(size: int) -> set[tuple[int, int]]:
    """Two walls that divide the grid in an S (Fig 5.1b): one rises from the bottom edge two
    columns left of the goal, one hangs from the top edge two columns right of it, each up to the
    goal's row. Cells beyond them must walk around a wall end to reach the goal."""
    c = size // 2
    return {(c - 2, y) for y in range(0, c + 1)} | {(c + 2, y) for y in range(c, size)}


class GridWorld(World):
    kind = "gridworld"

    def __init__(self, world_id: str = "g0", seed: int = 0, size: int = 9, barrier: bool = False,
                 actions: int = 4, goal: tuple[int, int] | None = None, max_episode_steps: int = 100) -> None:
        super().__init__(world_id, seed)
        if size < 3:
            raise ValueError("size must be >= 3")
        if actions not in (4, 8):
            raise ValueError("actions must be 4 or 8")
        self.size = size
        self.barrier = barrier
        self.moves = MOVES4 if actions == 4 else MOVES8
        self.names = NAMES4 if actions == 4 else NAMES8
        self.goal = goal if goal is not None else (size // 2, size // 2)
        self.max_episode_steps = max_episode_steps
        self.walls = barrier_cells(size) if barrier else set()
        if self.goal in self.walls or not (0 <= self.goal[0] < size and 0 <= self.goal[1] < size):
            raise ValueError(f"goal {self.goal} is not a free cell")
        self.cells = [(x, y) for y in range(size) for x in range(size) if (x, y) not in self.walls]
        self.index = {c: i for i, c in enumerate(self.cells)}
        # Opaque state ids: a fixed shuffle, so ids carry no geometry.
        self.state_id = np.random.default_rng(10_000 + seed).permutation(len(self.cells)).astype(np.int32)
        self.pos = self.goal
        self.t = 0

    @classmethod
    def from_params(cls, world_id: str, seed: int, params: Mapping[str, Any]) -> "GridWorld":
        goal = param(params, "goal", None)
        if goal is not None:
            try:
                gx, gy = (int(v) for v in str(goal).split(","))
            except ValueError:
                raise ValueError(f"parameter goal={goal!r}: expected 'x,y'") from None
            goal = (gx, gy)
        return cls(world_id, seed, size=param(params, "size", 9, int),
                   barrier=param(params, "barrier", False, bool), actions=param(params, "actions", 4, int),
                   goal=goal, max_episode_steps=param(params, "max_episode_steps", 100, int))

    def spec(self) -> WorldSpec:
        n = len(self.cells)
        return WorldSpec(
            world_id=self.world_id, kind=self.kind,
            sensors=(SensorSpec("state", "int32", (1,), 0, n - 1, "opaque state id (shuffled cell index)"),),
            action_space=ActionSpace(n=len(self.moves), names=self.names), reward_min=0.0, reward_max=1.0,
            program="gridworld", n_starts=n,
            params={"size": str(self.size), "barrier": str(self.barrier).lower(),
                    "actions": str(len(self.moves)), "goal": f"{self.goal[0]},{self.goal[1]}"},
        )

    def _obs(self, reward: float, done: bool) -> StepResult:
        sid = self.state_id[self.index[self.pos]]
        return StepResult({"state": np.array([sid], dtype=np.int32)}, reward, done)

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        start = self.pick_start(seed, start, len(self.cells))
        self.pos = self.cells[start]
        self.t = 0
        return self._obs(0.0, self.pos == self.goal)

    def step(self, action: np.ndarray) -> StepResult:
        a = int(np.asarray(action).reshape(-1)[0])
        if not 0 <= a < len(self.moves):
            raise ValueError(f"action {a} out of range 0..{len(self.moves) - 1}")
        dx, dy = self.moves[a]
        nxt = (self.pos[0] + dx, self.pos[1] + dy)
        if 0 <= nxt[0] < self.size and 0 <= nxt[1] < self.size and nxt not in self.walls:
            self.pos = nxt
        self.t += 1
        at_goal = self.pos == self.goal
        return self._obs(1.0 if at_goal else 0.0, at_goal or self.t >= self.max_episode_steps)

    def truth(self) -> Truth:
        pos = np.array(self.cells, dtype=np.float64)
        return Truth(self.world_id, "start_states", {"positions": pos})
