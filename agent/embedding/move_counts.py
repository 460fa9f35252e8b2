"""The moves distance between discrete traces: the Euclidean distance between how many times each
action (symbol) occurs in each trace; the order of the moves does not count.

Why: where actions are moves that add up (a step east, a step south; MiniGrid's forward in each
frame of the start, `rotation_frames`), a deterministic trace's counts are a linear function of
where it starts: the goal minus the sum of its moves. Two cells either side of a wall have traces
that differ in the detour, but the detour's steps there and back are added to opposite moves, so
they move the counts off the plane the places span, not along it: classical MDS of these distances
keeps the places where the edit distance (a distance along the ways) bends them round the wall.
It is the discrete form of `distance=net` (the sum of one-hot actions). Symbols in `skip` (turns:
they change the frame, not the place) are left out.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np


def move_counts(traces: Sequence[Sequence[int]], symbols: int, skip: Iterable[int] = ()) -> np.ndarray:
    """[n, symbols] how many times each symbol occurs in each trace (columns in `skip` zero)."""
    C = np.zeros((len(traces), max(int(symbols), 1)), dtype=np.float64)
    for i, t in enumerate(traces):
        a = np.asarray(t, dtype=np.int64)
        if a.size and (a.min() < 0 or a.max() >= C.shape[1]):
            raise ValueError(f"trace {i} has a symbol outside 0..{C.shape[1] - 1}")
        C[i] = np.bincount(a, minlength=C.shape[1])
    drop = [int(s) for s in skip if 0 <= int(s) < C.shape[1]]
    C[:, drop] = 0.0
    return C


def move_count_distances(traces: Sequence[Sequence[int]], symbols: int, skip: Iterable[int] = ()) -> np.ndarray:
    """[n, n] Euclidean distances between the traces' `move_counts`."""
    C = move_counts(traces, symbols, skip)
    sq = np.square(C).sum(axis=1)
    D2 = np.maximum(sq[:, None] + sq[None, :] - 2.0 * (C @ C.T), 0.0)
    D = np.sqrt(D2)
    np.fill_diagonal(D, 0.0)
    return (D + D.T) / 2


__all__ = ["move_count_distances", "move_counts"]
