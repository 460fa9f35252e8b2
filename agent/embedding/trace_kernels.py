"""Compiled kernels for continuous trace distances (numba, parallel over rows), each with a numpy
reference implementation that is used when numba is not installed and that the tests compare with.

Traces arrive padded to one array [n, L, d] (see `pad_traces`); DTW also takes the true lengths.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.distance import cdist

try:  # numba is an accelerator, not a requirement of the maths
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only without numba
    HAVE_NUMBA = False


# --- numpy references --------------------------------------------------------------------------


def padded_sum_pairs_numpy(X: np.ndarray, out: np.ndarray) -> None:
    """Reference of `padded_sum_pairs` (numpy)."""
    out[:] = 0
    for t in range(X.shape[1]):
        step = X[:, t, :]
        if step.any():
            out += cdist(step, step).astype(out.dtype, copy=False)
    np.fill_diagonal(out, 0)


def padded_sum_cross_numpy(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """Reference of `padded_sum_cross` (numpy)."""
    out[:] = 0
    for t in range(A.shape[1]):
        out += cdist(A[:, t, :], B[:, t, :]).astype(out.dtype, copy=False)


def dtw_numpy(a: np.ndarray, b: np.ndarray, penalty: float = 0.0) -> float:
    """Reference DTW distance of two unpadded traces [la, d] and [lb, d] (numpy); `penalty` is
    added for every step that repeats an action of one trace (a move off the diagonal), so that
    trace length stays in the cost."""
    n, m = len(a), len(b)
    if n == 0 or m == 0:
        return float(np.linalg.norm(a, axis=1).sum() + np.linalg.norm(b, axis=1).sum())
    C = cdist(a, b)
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            acc[i, j] = C[i - 1, j - 1] + min(acc[i - 1, j] + penalty, acc[i, j - 1] + penalty, acc[i - 1, j - 1])
    return float(acc[n, m])


# --- numba kernels -----------------------------------------------------------------------------

if HAVE_NUMBA:

    @numba.njit(cache=True, nogil=True)
    def _pair_sum(A, i, B, j):  # pragma: no cover - compiled
        """sum_t ||A[i, t] - B[j, t]||: the padded-sum distance of one pair."""
        s = 0.0
        L, d = A.shape[1], A.shape[2]
        for t in range(L):
            acc = 0.0
            for c in range(d):
                diff = A[i, t, c] - B[j, t, c]
                acc += diff * diff
            s += np.sqrt(acc)
        return s

    @numba.njit(cache=True, nogil=True)
    def _fill_row(X, i, out):  # pragma: no cover - compiled
        out[i, i] = 0
        for j in range(i + 1, X.shape[0]):
            v = _pair_sum(X, i, X, j)
            out[i, j] = v
            out[j, i] = v

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _padded_sum_pairs(X, out):  # pragma: no cover - compiled
        n = X.shape[0]
        # rows r and n-1-r in one task: every task gets the same share of the upper triangle
        for r in numba.prange((n + 1) // 2):
            _fill_row(X, r, out)
            if n - 1 - r != r:
                _fill_row(X, n - 1 - r, out)

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _padded_sum_cross(A, B, out):  # pragma: no cover - compiled
        for i in numba.prange(A.shape[0]):
            for j in range(B.shape[0]):
                out[i, j] = _pair_sum(A, i, B, j)

    @numba.njit(cache=True, nogil=True)
    def _dtw(a, la, b, lb, buf, pen):  # pragma: no cover - compiled
        if la == 0 or lb == 0:
            s = 0.0
            for t in range(la):
                s += np.sqrt(np.sum(a[t] * a[t]))
            for t in range(lb):
                s += np.sqrt(np.sum(b[t] * b[t]))
            return s
        d = a.shape[1]
        inf = np.inf
        prev = buf[0]
        cur = buf[1]
        for j in range(lb + 1):
            prev[j] = inf
        prev[0] = 0.0
        for i in range(1, la + 1):
            cur[0] = inf
            for j in range(1, lb + 1):
                acc = 0.0
                for c in range(d):
                    diff = a[i - 1, c] - b[j - 1, c]
                    acc += diff * diff
                best = prev[j] + pen
                if cur[j - 1] + pen < best:
                    best = cur[j - 1] + pen
                if prev[j - 1] < best:
                    best = prev[j - 1]
                cur[j] = np.sqrt(acc) + best
            prev, cur = cur, prev
        return prev[lb]

    @numba.njit(parallel=True, cache=True, nogil=True)
    def _dtw_cross(A, la, B, lb, out, symmetric, pen):  # pragma: no cover - compiled
        na, nb = A.shape[0], B.shape[0]
        for i in numba.prange(na):
            buf = np.empty((2, B.shape[1] + 1))
            start = i + 1 if symmetric else 0
            for j in range(start, nb):
                v = _dtw(A[i], la[i], B[j], lb[j], buf, pen)
                out[i, j] = v
                if symmetric:
                    out[j, i] = v
            if symmetric:
                out[i, i] = 0.0


def padded_sum_pairs(X: np.ndarray, out: np.ndarray) -> None:
    """Fill `out` [n, n] with the padded-sum distances between the traces of X [n, L, d]."""
    if HAVE_NUMBA:
        _padded_sum_pairs(np.ascontiguousarray(X, dtype=np.float64), out)
    else:
        padded_sum_pairs_numpy(X, out)


def padded_sum_cross(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """Fill `out` [na, nb] with the padded-sum distances from the traces of A to those of B."""
    if HAVE_NUMBA:
        _padded_sum_cross(np.ascontiguousarray(A, dtype=np.float64), np.ascontiguousarray(B, dtype=np.float64), out)
    else:
        padded_sum_cross_numpy(A, B, out)


def dtw_cross(
    A: np.ndarray,
    la: np.ndarray,
    B: np.ndarray,
    lb: np.ndarray,
    out: np.ndarray,
    symmetric: bool = False,
    penalty: float = 0.0,
) -> None:
    """Fill `out` with the DTW distances from A to B (true lengths la, lb); `symmetric` when A is B;
    `penalty` per off-diagonal move (see `dtw_numpy`)."""
    if HAVE_NUMBA:
        _dtw_cross(
            np.ascontiguousarray(A, dtype=np.float64),
            la.astype(np.int64),
            np.ascontiguousarray(B, dtype=np.float64),
            lb.astype(np.int64),
            out,
            symmetric,
            float(penalty),
        )
        return
    for i in range(A.shape[0]):
        for j in range(B.shape[0]):
            out[i, j] = dtw_numpy(A[i, : la[i]], B[j, : lb[j]], penalty)
