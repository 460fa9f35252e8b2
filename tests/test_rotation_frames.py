"""Traces in the frame of the start (agent.embedding.rotation_frames): rotations found from
transitions, relabelled traces, and the MiniGrid fold they remove."""

from __future__ import annotations

import numpy as np

from sensorimotor.agent.embedding import classical_mds, procrustes_error, trace_distances
from sensorimotor.agent.embedding.rotation_frames import Rotations, find_rotations, frame_trace

DIRS = ((1, 0), (0, 1), (-1, 0), (0, -1))  # east, south, west, north (MiniGrid's order)


def _egocentric_table(n: int = 5) -> dict[tuple[bytes, int], bytes]:
    """Transitions of an n x n room with actions 0 left, 1 right, 2 forward, 3 a no-op."""

    def key(x: int, y: int, d: int) -> bytes:
        return bytes([x, y, d])

    nxt = {}
    for x in range(n):
        for y in range(n):
            for d in range(4):
                fx, fy = x + DIRS[d][0], y + DIRS[d][1]
                fwd = (fx, fy, d) if 0 <= fx < n and 0 <= fy < n else (x, y, d)
                for a, to in enumerate(((x, y, (d - 1) % 4), (x, y, (d + 1) % 4), fwd, (x, y, d))):
                    nxt[(key(x, y, d), a)] = key(*to)
    return nxt


def _allocentric_table(n: int = 5) -> dict[tuple[bytes, int], bytes]:
    """Transitions of an n x n grid with moves east, south, west, north (a wall stops a move)."""
    nxt = {}
    for x in range(n):
        for y in range(n):
            for a, (dx, dy) in enumerate(DIRS):
                tx, ty = min(max(x + dx, 0), n - 1), min(max(y + dy, 0), n - 1)
                nxt[(bytes([x, y]), a)] = bytes([tx, ty])
    return nxt


def test_turns_are_found_as_rotations_and_moves_are_not():
    rot = find_rotations(_egocentric_table(), range(4))
    assert rot == Rotations(4, ((0, 1), (1, 3)))  # left generates; right is three lefts
    assert rot.power(2) is None and rot.power(3) is None
    assert find_rotations(_allocentric_table(), range(4)) is None  # a move repeated never comes back
    assert find_rotations({}, range(4)) is None
    few = dict(list(_egocentric_table(2).items())[:10])
    assert find_rotations(few, range(4)) is None  # too little evidence


def test_frame_trace_relabels_moves_by_the_turns_before_them():
    rot = Rotations(4, ((0, 1), (1, 3)))
    assert frame_trace([2, 2, 1, 2], rot, 4) == [6, 6, 1, 18]  # forward, forward, right (3 lefts), forward
    assert frame_trace([0, 2], rot, 4) == [0, 10]  # after one left
    assert frame_trace([2, 2, 1, 2], rot, 4) != frame_trace([2, 1, 2, 2], rot, 4)


def test_frames_remove_the_fold_of_egocentric_traces():
    # the traces of MiniGrid Empty 8x8 facing east: F^a R F^b to the goal at the far corner
    cells = [(x, y) for y in range(1, 7) for x in range(1, 7) if (x, y) != (6, 6)]
    traces = [[2] * (6 - x) + ([1] if y < 6 else []) + [2] * (6 - y) for x, y in cells]
    truth = np.array(cells, dtype=np.float64)

    def err(ts: list[list[int]]) -> float:
        return procrustes_error(
            truth, classical_mds(trace_distances(ts, kind="edit", substitution_cost=2), 2).coordinates
        )

    rot = find_rotations(_egocentric_table(), range(4))
    assert rot is not None
    assert round(err(traces), 3) == 0.250  # the fold
    assert err([frame_trace(t, rot, 7) for t in traces]) < 0.025


def test_mean_trace_distances_compare_trace_distributions_step_by_step():
    from sensorimotor.agent.embedding.probabilistic import mean_trace_distances, mean_traces

    samples = [[[0, 1], [0, 0]], [[1, 1], [1, 1]], [[0, 1, 1, 1], [0]]]
    reached = [[True, True], [True, True], [True, False]]
    M = mean_traces(samples, 2, reached, horizon=2)
    assert M.shape == (3, 2, 2) and M[0, 1].tolist() == [0.5, 0.5] and M[2, 1].tolist() == [0.0, 1.0]
    D = mean_trace_distances(samples, 2, reached, horizon=2)
    assert D[0, 1] == 3.0 and D[0, 2] == 1.0 and np.allclose(D, D.T) and np.all(np.diag(D) == 0)
    # every sample of a start failed: all of them count
    assert mean_traces([[[0]], [[1]]], 2, [[False], [False]]).shape == (2, 1, 2)
