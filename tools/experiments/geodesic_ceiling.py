"""How far a map of ways round walls is from a map of places: for a MiniGrid layout, classical MDS
of the true shortest-path distances between its start cells (4-neighbour moves through free cells),
scored against the cells' places by the Procrustes error. The edit distance between traces is a
distance along the ways, so on a layout with walls this is about as near the cells as it comes.
Beside it, the same distances embedded by weighted MDS (`agent.embedding.weighted_mds`), and the
map the generic program's default makes of a shortest-way policy's traces: the moves distance
(`agent.embedding.move_counts`, how many steps each way) embedded by weighted MDS.

    python -m sensorimotor.tools.experiments.geodesic_ceiling gym:MiniGrid-LavaGapS7-v0 --seeds 0 1 2
"""

from __future__ import annotations

import argparse
from collections import deque
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, procrustes_error
from sensorimotor.agent.embedding.move_counts import move_count_distances
from sensorimotor.agent.embedding.weighted_mds import weighted_mds
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


MOVES = ((1, 0), (0, 1), (-1, 0), (0, -1))


def shortest_traces(cells: list[tuple[int, int]], free: set[tuple[int, int]], goal: tuple[int, int]) -> list[list[int]]:
    """Each cell's shortest way to `goal` through `free` cells, as moves (indices into MOVES; ties
    broken by move order: one deterministic optimal policy). A cell with no way gets []."""
    dist = {goal: 0}
    queue = deque([goal])
    while queue:
        a = queue.popleft()
        for dx, dy in MOVES:
            b = (a[0] + dx, a[1] + dy)
            if b in free and b not in dist:
                dist[b] = dist[a] + 1
                queue.append(b)
    out = []
    for c in cells:
        t: list[int] = []
        while c in dist and c != goal:
            m = next(i for i, (dx, dy) in enumerate(MOVES) if dist.get((c[0] + dx, c[1] + dy), -2) == dist[c] - 1)
            t.append(m)
            c = (c[0] + MOVES[m][0], c[1] + MOVES[m][1])
        out.append(t)
    return out


def geodesic_errors(world: Any) -> dict[str, float]:
    """Procrustes errors against the cells: classical and weighted MDS of their shortest-path
    distances, and weighted MDS of the moves distance between their shortest ways to the goal."""
    u = world.u
    pos = np.asarray(world.truth().tensors["positions"], dtype=np.float64)
    cells = [(int(x), int(y)) for x, y in pos]
    goals = [
        (x, y)
        for y in range(u.height)
        for x in range(u.width)
        if u.grid.get(x, y) is not None and u.grid.get(x, y).type == "goal"
    ]
    free = set(cells) | set(goals)
    D = shortest_paths(cells, free)
    D[~np.isfinite(D)] = D[np.isfinite(D)].max() * 2
    M = move_count_distances(shortest_traces(cells, free, goals[0]), len(MOVES))
    return {
        "classical": procrustes_error(pos, classical_mds(D, 2).coordinates),
        "weighted": procrustes_error(pos, weighted_mds(D, 2).coordinates),
        "moves": procrustes_error(pos, weighted_mds(M, 2).coordinates),
    }


def geodesic_error(world: Any) -> float:
    """The Procrustes error against the cells of the classical MDS of their shortest-path distances."""
    return geodesic_errors(world)["classical"]


def main(world: str, seeds: list[int]) -> dict[int, dict[str, float]]:
    out = {}
    for seed in seeds:
        with make_world(world, None, seed, {}) as w:
            out[seed] = e = geodesic_errors(w)
        print(
            f"{world} seed {seed}: against the cells, shortest-path distances by classical MDS {e['classical']:.3f}, "
            f"by weighted MDS {e['weighted']:.3f}; moves distance of shortest ways, weighted MDS {e['moves']:.3f}"
        )
    return out


if __name__ == "__main__":
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("world", help="a MiniGrid world, gym:MiniGrid-...")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="layouts (the world's seed draws one)")
    a = p.parse_args()
    main(a.world, a.seeds)
