"""Distances between action traces (ch. 3, Eq 3.1 and Algorithm 1).

Continuous actions: pad the shorter trace with zero actions (appended by default, prepended as in
Fig 5.5a) and sum the per-step Euclidean distances - a metric on traces. Discrete actions: edit
distance between the action-index sequences (unit insertion/deletion cost, `substitution_cost`
for substitutions; 2 gives the indel/LCS distance, which equals the Manhattan distance between grid
cells when traces move in a consistent order). Dynamic time warping (`kind="dtw"`) is offered as
an option; it is *not* a metric (no triangle inequality), so MDS of it may show large negative
eigenvalues.

Continuous kernels are compiled (numba, parallel); edit distances use rapidfuzz (compiled, all
cores). `dtype=np.float32` halves the n x n matrix.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import DTypeLike

from sensorimotor.agent.embedding import trace_kernels as K

PADDINGS = ("append", "prepend")
KINDS = ("continuous", "edit", "dtw")


def _as_2d(traces: Sequence) -> list[np.ndarray]:
    arrs = [np.asarray(t, dtype=np.float64) for t in traces]
    arrs = [a.reshape(-1, 1) if a.ndim == 1 else a for a in arrs]
    if not arrs:
        raise ValueError("no traces")
    d = arrs[0].shape[1]
    if any(a.ndim != 2 or a.shape[1] != d for a in arrs):
        raise ValueError("every continuous trace must be an array [length, action_dims] with the same action_dims")
    if any(not np.isfinite(a).all() for a in arrs):
        raise ValueError("traces contain NaN or inf")
    return arrs


def pad_traces(traces: Sequence[np.ndarray], pad: str = "append", length: int | None = None) -> np.ndarray:
    """Stack continuous traces (each [L_i, d]) into one [n, L, d] array padded with zero actions;
    L = `length` or the longest trace. Any common L gives the same padded-sum distances."""
    if pad not in PADDINGS:
        raise ValueError(f"pad must be one of {PADDINGS}, not {pad!r}")
    arrs = _as_2d(traces)
    L = max(max(a.shape[0] for a in arrs), length or 0, 1)
    out = np.zeros((len(arrs), L, arrs[0].shape[1]))
    for i, a in enumerate(arrs):
        if a.shape[0]:
            if pad == "append":
                out[i, : a.shape[0]] = a
            else:
                out[i, L - a.shape[0] :] = a
    return out


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, not {kind!r}")


def _edit(a: Sequence, b: Sequence, substitution_cost: int, dtype: np.dtype) -> np.ndarray:
    from rapidfuzz.distance import Levenshtein
    from rapidfuzz.process import cdist as rf_cdist

    if substitution_cost < 1:
        raise ValueError("substitution_cost must be >= 1")
    sa = [[int(x) for x in t] for t in a]
    sb = sa if b is a else [[int(x) for x in t] for t in b]
    if not sa or not sb:
        raise ValueError("no traces")
    D = rf_cdist(
        sa,
        sb,
        scorer=Levenshtein.distance,
        dtype=np.int32,
        workers=-1,
        scorer_kwargs={"weights": (1, 1, int(substitution_cost))},
    )
    return D.astype(dtype)


def trace_distances(
    traces: Sequence,
    kind: str = "continuous",
    pad: str = "append",
    substitution_cost: int = 1,
    dtype: DTypeLike = np.float64,
    dtw_penalty: float = 0.0,
) -> np.ndarray:
    """The n x n matrix of pairwise trace distances (zero diagonal, symmetric).

    Parameters
    ----------
    traces : sequence
        Continuous traces (each [L_i, action_dims] or [L_i]) or, for "edit", sequences of action
        indices.
    kind : {"continuous", "edit", "dtw"}, default "continuous"
        Padded sum of per-step Euclidean distances (a metric), edit distance of action indices,
        or dynamic time warping (not a metric).
    pad : {"append", "prepend"}, default "append"
        Where the shorter continuous trace gets its zero actions.
    substitution_cost : int, default 1
        Edit-distance cost of a substitution (2: the indel/LCS distance).
    dtype : dtype-like, default np.float64
        Element type of the result (`np.float32` halves its memory).
    dtw_penalty : float, default 0.0
        "dtw": cost of each off-diagonal move (plain DTW repeats a step for free; a penalty keeps
        the difference of trace lengths in the distance).

    Returns
    -------
    np.ndarray
        [n, n] distances.

    Examples
    --------
    Indel distances between three discrete traces::

        D = trace_distances([[0, 0, 1], [0, 1], [1]], kind="edit", substitution_cost=2)
        # D[0, 2] == 2.0: two deletions turn [0, 0, 1] into [1]
    """
    _check_kind(kind)
    if kind == "edit":
        return _edit(traces, traces, substitution_cost, np.dtype(dtype))
    if kind == "dtw":
        arrs = _as_2d(traces)
        X, lens = pad_traces(arrs), np.array([a.shape[0] for a in arrs])
        out = np.zeros((len(arrs), len(arrs)), dtype=dtype)
        K.dtw_cross(X, lens, X, lens, out, symmetric=True, penalty=dtw_penalty)
        return out
    X = pad_traces(traces, pad)
    out = np.empty((X.shape[0], X.shape[0]), dtype=dtype)
    K.padded_sum_pairs(X, out)
    return out


def trace_cross_distances(
    a: Sequence,
    b: Sequence,
    kind: str = "continuous",
    pad: str = "append",
    substitution_cost: int = 1,
    dtype: DTypeLike = np.float64,
) -> np.ndarray:
    """Distances from each trace in `a` to each trace in `b`: [len(a), len(b)]."""
    _check_kind(kind)
    if kind == "edit":
        return _edit(a, b, substitution_cost, np.dtype(dtype))
    A, B = _as_2d(a), _as_2d(b)
    if kind == "dtw":
        L = max(max(x.shape[0] for x in A + B), 1)
        out = np.zeros((len(A), len(B)), dtype=dtype)
        K.dtw_cross(
            pad_traces(A, length=L),
            np.array([x.shape[0] for x in A]),
            pad_traces(B, length=L),
            np.array([x.shape[0] for x in B]),
            out,
        )
        return out
    L = max(max(x.shape[0] for x in A + B), 1)
    out = np.empty((len(A), len(B)), dtype=dtype)
    K.padded_sum_cross(pad_traces(A, pad, L), pad_traces(B, pad, L), out)
    return out


def update_trace_distances(
    D: np.ndarray,
    traces: Sequence,
    changed: Sequence[int],
    kind: str = "continuous",
    pad: str = "append",
    substitution_cost: int = 1,
) -> np.ndarray:
    """Recompute, in place, only the rows and columns of `D` whose traces changed; returns `D`.
    Costs O(len(changed) * n) trace comparisons instead of O(n^2)."""
    idx = np.unique(np.asarray(changed, dtype=np.int64))
    if idx.size == 0:
        return D
    if D.shape != (len(traces), len(traces)):
        raise ValueError(f"D is {D.shape}, traces are {len(traces)}")
    rows = trace_cross_distances([traces[i] for i in idx], traces, kind, pad, substitution_cost, D.dtype)
    D[idx, :] = rows
    D[:, idx] = rows.T
    D[idx, idx] = 0
    return D


def continuous_trace_distances(traces: Sequence[np.ndarray], pad: str = "append") -> np.ndarray:
    """`trace_distances` of continuous traces (padded sum of per-step distances)."""
    return trace_distances(traces, "continuous", pad)


def edit_trace_distances(traces: Sequence[Sequence[int]], substitution_cost: int = 1) -> np.ndarray:
    """`trace_distances` of discrete traces (edit distance of action indices)."""
    return trace_distances(traces, "edit", substitution_cost=substitution_cost)


class PreparedTraces:
    """Traces converted once to the form the kernels take (padded array, lengths, or integer
    sequences), for repeated distance queries against members (landmark selection, streaming)."""

    def __init__(
        self, traces: Sequence, kind: str = "continuous", pad: str = "append", substitution_cost: int = 1
    ) -> None:
        _check_kind(kind)
        self.kind, self.pad, self.substitution_cost = kind, pad, substitution_cost
        self.n = len(traces)
        if kind == "edit":
            self._seqs = [[int(x) for x in t] for t in traces]
        else:
            arrs = _as_2d(traces)
            self._X = pad_traces(arrs, pad)
            self._lens = np.array([a.shape[0] for a in arrs])

    def subset(self, rows: np.ndarray) -> PreparedTraces:
        """The traces at `rows`, prepared (copied once)."""
        sub = object.__new__(PreparedTraces)
        sub.kind, sub.pad, sub.substitution_cost, sub.n = self.kind, self.pad, self.substitution_cost, len(rows)
        if self.kind == "edit":
            sub._seqs = [self._seqs[i] for i in rows]
        else:
            sub._X, sub._lens = np.ascontiguousarray(self._X[rows]), self._lens[rows]
        return sub

    def distances_to(
        self, idx: np.ndarray, rows: np.ndarray | None = None, dtype: DTypeLike = np.float64
    ) -> np.ndarray:
        """[len(rows) or n, len(idx)]: the traces at `rows` (default all) against those at `idx`."""
        idx = np.asarray(idx, dtype=np.int64)
        if self.kind == "edit":
            left = self._seqs if rows is None else [self._seqs[i] for i in rows]
            return _edit(left, [self._seqs[i] for i in idx], self.substitution_cost, np.dtype(dtype))
        A = self._X if rows is None else self._X[rows]
        la = self._lens if rows is None else self._lens[rows]
        out = np.empty((A.shape[0], idx.size), dtype=dtype)
        if self.kind == "dtw":
            out[:] = 0
            K.dtw_cross(A, la, self._X[idx], self._lens[idx], out)
        else:
            K.padded_sum_cross(A, np.ascontiguousarray(self._X[idx]), out)
        return out
