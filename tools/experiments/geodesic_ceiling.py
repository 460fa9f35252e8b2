"""How far a map of ways round walls is from a map of places: for a MiniGrid layout, classical MDS
of the true shortest-path distances between its start cells (4-neighbour moves through free cells),
scored against the cells' places by the Procrustes error. A trace map is a map of ways, so on a
layout with walls this is about as near the cells as any trace metric can come.

    python -m sensorimotor.tools.experiments.geodesic_ceiling gym:MiniGrid-LavaGapS7-v0 --seeds 0 1 2
"""

from __future__ import annotations

import argparse
from collections import deque
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, procrustes_error
from sensorimotor.worlds.registry import make_world


def shortest_paths(cells: list[tuple[int, int]], free: set[tuple[int, int]]) -> np.ndarray:
    """Breadth-first distances between `cells` through `free` cells (inf where none)."""
    D = np.full((len(cells), len(cells)), np.inf)
    for i, c in enumerate(cells):
        dist = {c: 0}
        queue = deque([c])
        while queue:
            a = queue.popleft()
            for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                b = (a[0] + dx, a[1] + dy)
                if b in free and b not in dist:
                    dist[b] = dist[a] + 1
                    queue.append(b)
        D[i] = [dist.get(c2, np.inf) for c2 in cells]
    return D


def geodesic_error(world: Any) -> float:
    """The Procrustes error against the cells of the MDS of their shortest-path distances."""
    u = world.u
    pos = np.asarray(world.truth().tensors["positions"], dtype=np.float64)
    cells = [(int(x), int(y)) for x, y in pos]
    free = set(cells) | {
        (x, y)
        for y in range(u.height)
        for x in range(u.width)
        if u.grid.get(x, y) is not None and u.grid.get(x, y).type == "goal"
    }
    D = shortest_paths(cells, free)
    D[~np.isfinite(D)] = D[np.isfinite(D)].max() * 2
    return procrustes_error(pos, classical_mds(D, 2).coordinates)


def main(world: str, seeds: list[int]) -> dict[int, float]:
    out = {}
    for seed in seeds:
        with make_world(world, None, seed, {}) as w:
            out[seed] = geodesic_error(w)
        print(f"{world} seed {seed}: shortest-path MDS against the cells {out[seed]:.3f}")
    return out


if __name__ == "__main__":
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("world", help="a MiniGrid world, gym:MiniGrid-...")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="layouts (the world's seed draws one)")
    a = p.parse_args()
    main(a.world, a.seeds)
