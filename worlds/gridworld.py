"""Gridworld (ch. 5, Fig 5.1): a 9x9 grid, goal in the centre, reward 1 on entering the goal.

The agent sees only an opaque state id (cells are numbered in a shuffled order), never the cell
coordinates; those are the ground truth its embedding is scored against. The `barrier` variant
places a wall that divides most of the grid (Fig 5.1b). Moves into walls or off the grid stay put.
With `slip` > 0 transitions are stochastic (ch. 9.4): a move goes to one of its two sideways
neighbours with that probability (half each); the default 0 keeps the world deterministic.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.protocol.messages import ActionSpace, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import option, parse
from sensorimotor.worlds.base import StepResult, World

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


@dataclass(frozen=True)
class GridWorldParams:
    """Parameters of the gridworld (Fig 5.1)."""

    size: int = option(9, "side of the square grid, in cells", min=3)
    barrier: bool = option(False, "walls that divide the grid in an S (Fig 5.1b)")
    actions: int = option(4, "moves: 4 (compass) or 8 (with diagonals)", choices=(4, 8))
    goal: tuple[int, int] | None = option(None, "goal cell x,y (none: the centre)")
    max_episode_steps: int = option(100, "steps after which an episode ends without the goal", min=1)
    slip: float = option(0.0, "probability that a move goes sideways instead (ch. 9.4)", min=0.0, max=1.0)


@dataclass(frozen=True)
class BarrierGridWorldParams(GridWorldParams):
    """Parameters of `gridworld-barrier`: the gridworld with the barrier on by default."""

    barrier: bool = option(True, "walls that divide the grid in an S (Fig 5.1b)")


class GridWorld(World):
    """The gridworld of Fig 5.1: an opaque state id in, one of 4 (or 8) moves out, reward 1 at the goal.

    Parameters
    ----------
    world_id : str, default="g0"
        The world's id on the bus.
    seed : int, default=0
        Seeds the random starts and the shuffle of the state ids.
    params : GridWorldParams or None, default=None
        The parameters (default: `GridWorldParams()`).
    **overrides
        Parameter values applied over `params` (``size=7``, ``barrier=True``...), checked by
        `protocol.params.parse`.

    Raises
    ------
    ParamError
        For an unknown or invalid parameter.
    ValueError
        If the goal is not a free cell.

    Examples
    --------
    >>> import numpy as np
    >>> w = GridWorld("grid0", seed=0, size=5)
    >>> w.spec().n_starts
    25
    >>> r = w.reset(start=0)
    >>> r.tensors["state"].shape
    (1,)
    """

    kind = "gridworld"
    Params = GridWorldParams

    def __init__(
        self, world_id: str = "g0", seed: int = 0, params: GridWorldParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(GridWorldParams, overrides, name=self.kind, base=params)
        size, barrier, actions, goal = prm.size, prm.barrier, prm.actions, prm.goal
        max_episode_steps = prm.max_episode_steps
        self.size = size
        self.barrier = barrier
        self.moves = MOVES4 if actions == 4 else MOVES8
        self.names = NAMES4 if actions == 4 else NAMES8
        self.goal = goal if goal is not None else (size // 2, size // 2)
        self.max_episode_steps = max_episode_steps
        self.slip = float(prm.slip)
        self.walls = barrier_cells(size) if barrier else set()
        if self.goal in self.walls or not (0 <= self.goal[0] < size and 0 <= self.goal[1] < size):
            raise ValueError(f"goal {self.goal} is not a free cell")
        self.cells = [(x, y) for y in range(size) for x in range(size) if (x, y) not in self.walls]
        self.index = {c: i for i, c in enumerate(self.cells)}
        # Opaque state ids: a fixed shuffle, so ids carry no geometry.
        self.state_id = np.random.default_rng(10_000 + seed).permutation(len(self.cells)).astype(np.int32)
        self.pos = self.goal
        self.t = 0

    def spec(self) -> WorldSpec:
        """One int32 sensor ``state`` (the opaque id), discrete moves, one start state per free cell."""
        n = len(self.cells)
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=(SensorSpec("state", "int32", (1,), 0, n - 1, "opaque state id (shuffled cell index)"),),
            action_space=ActionSpace(n=len(self.moves), names=self.names),
            reward_min=0.0,
            reward_max=1.0,
            program="gridworld",
            n_starts=n,
            params={
                "size": str(self.size),
                "barrier": str(self.barrier).lower(),
                "actions": str(len(self.moves)),
                "goal": f"{self.goal[0]},{self.goal[1]}",
            }
            | ({"slip": str(self.slip)} if self.slip else {}),
        )

    def _obs(self, reward: float, done: bool) -> StepResult:
        sid = self.state_id[self.index[self.pos]]
        return StepResult({"state": np.array([sid], dtype=np.int32)}, reward, done)

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Start in free cell `start` (in `truth` order) or a random one; ``done`` at once on the goal."""
        start = self.pick_start(seed, start, len(self.cells))
        self.pos = self.cells[start]
        self.t = 0
        return self._obs(0.0, self.pos == self.goal)

    def step(self, action: np.ndarray) -> StepResult:
        """Move (``action[0]`` indexes the moves; into a wall or off the grid stays put); reward 1 on the goal."""
        a = int(np.asarray(action).reshape(-1)[0])
        if not 0 <= a < len(self.moves):
            raise ValueError(f"action {a} out of range 0..{len(self.moves) - 1}")
        dx, dy = self.moves[a]
        if self.slip > 0 and self.rng.random() < self.slip:
            dx, dy = (-dy, dx) if self.rng.random() < 0.5 else (dy, -dx)  # sideways: a quarter turn
        nxt = (self.pos[0] + dx, self.pos[1] + dy)
        if 0 <= nxt[0] < self.size and 0 <= nxt[1] < self.size and nxt not in self.walls:
            self.pos = nxt
        self.t += 1
        at_goal = self.pos == self.goal
        return self._obs(1.0 if at_goal else 0.0, at_goal or self.t >= self.max_episode_steps)

    def truth(self) -> Truth:
        """The (x, y) cell of every start state, row i for start state i."""
        pos = np.array(self.cells, dtype=np.float64)
        return Truth(self.world_id, "start_states", {"positions": pos})
