"""Your first world, as a `World` subclass in your own package.

A walker on a 7 x 7 grid that senses only how strongly it hears 12 radio beacons (it is never told
where it is), with a reward for reaching the centre. The agent's generic program learns to walk to
the centre and, from the traces of that walk from every cell, a map of the grid.

Put this file in a package of yours (e.g. ``my_robot/beacons.py``), start ``sme agent``, then::

    python -m my_robot.beacons              # serves the world over the bus until Ctrl-C
    sme watch                               # another shell: embeddings as they arrive
"""

from __future__ import annotations

import argparse

import numpy as np

from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.protocol.messages import ActionSpace, SensorSpec, Truth, WorldSpec
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.node import WorldNode

MOVES = ((0, 1), (0, -1), (-1, 0), (1, 0))  # action 0 up, 1 down, 2 left, 3 right


class Beacons(World):
    """A walker on an n x n grid hearing 12 beacons; reward 1 at the centre."""

    kind = "beacons"

    def __init__(self, world_id: str = "beacons", seed: int = 0, n: int = 7) -> None:
        super().__init__(world_id, seed)
        self.n = n
        self.beacons = np.random.default_rng(100).uniform(-1, n, size=(12, 2))  # fixed places
        self.cells = [(x, y) for y in range(n) for x in range(n)]  # the start states, row by row
        self.goal = (n // 2, n // 2)
        self.pos, self.t = self.goal, 0

    def spec(self) -> WorldSpec:
        """One sensor of 12 floats, 4 discrete moves, one start state per cell, the generic program."""
        return WorldSpec(
            self.world_id,
            self.kind,
            (SensorSpec("beacons", "float32", (12,), 0.0, 1.0, "signal strength of each beacon"),),
            ActionSpace(n=4, names=("up", "down", "left", "right")),
            program="generic",  # no agent code for this world: the ch. 6 recipe learns it
            n_starts=len(self.cells),
        )

    def _observe(self, reward: float = 0.0, done: bool = False) -> StepResult:
        d = np.linalg.norm(self.beacons - np.asarray(self.pos, dtype=float), axis=1)
        return StepResult({"beacons": np.exp(-0.5 * (d / 2.5) ** 2).astype(np.float32)}, reward, done)

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        self.pos = self.cells[self.pick_start(seed, start, len(self.cells))]
        self.t = 0
        return self._observe(done=self.pos == self.goal)

    def step(self, action: np.ndarray) -> StepResult:
        dx, dy = MOVES[int(action[0])]
        x, y = self.pos[0] + dx, self.pos[1] + dy
        if 0 <= x < self.n and 0 <= y < self.n:  # walls hold the walker in
            self.pos = (x, y)
        self.t += 1
        at_goal = self.pos == self.goal
        return self._observe(1.0 if at_goal else 0.0, at_goal or self.t >= 50)

    def truth(self) -> Truth:
        """Where each start state really is: used to score the maps, never to learn."""
        return Truth(self.world_id, "start_states", {"positions": np.array(self.cells, dtype=np.float64)})


def main() -> None:
    p = argparse.ArgumentParser(description="serve the beacons world over the bus")
    p.add_argument("--connect", default="tcp/127.0.0.1:7447", help="the agent's router (default: sme agent's)")
    p.add_argument("--id", default="beacons", help="world id on the bus")
    p.add_argument("--seconds", type=float, default=None, help="stop after this long (default: Ctrl-C)")
    args = p.parse_args()
    with Beacons(args.id) as world, Bus(BusConfig.for_role("world", args.connect)) as bus:
        node = WorldNode(world, bus, args.id, seconds=args.seconds)
        node.install_signal_handlers()  # Ctrl-C and SIGTERM stop it cleanly
        stats = node.run()
    print(f"served {stats.steps} steps, {stats.episodes} episodes")


if __name__ == "__main__":
    main()
