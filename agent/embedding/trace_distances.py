"""Distances between action traces (ch. 3, Eq 3.1 and Algorithm 1).

Continuous actions: pad the shorter trace with zero actions (appended by default, prepended as in
Fig 5.5a) and sum the per-step Euclidean distances. Discrete actions: edit distance between the
action-index sequences (unit insertion/deletion cost, `substitution_cost` for substitutions; 2
gives the indel/LCS distance, which equals the Manhattan distance between grid cells when traces
move in a consistent order).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.spatial.distance import cdist

PADDINGS = ("append", "prepend")


def pad_traces(traces: Sequence[np.ndarray], pad: str = "append") -> np.ndarray:
    """Stack continuous traces (each [L_i, d]) into one [n, L_max, d] array padded with zeros."""
    if pad not in PADDINGS:
        raise ValueError(f"pad must be one of {PADDINGS}, not {pad!r}")
    arrs = [np.asarray(t, dtype=np.float64) for t in traces]
    if not arrs:
        raise ValueError("no traces")
    arrs = [a.reshape(-1, 1) if a.ndim == 1 else a for a in arrs]
    d = arrs[0].shape[1]
    if any(a.ndim != 2 or a.shape[1] != d for a in arrs):
        raise ValueError("every continuous trace must be an array [length, action_dims] with the same action_dims")
    if any(not np.isfinite(a).all() for a in arrs):
        raise ValueError("traces contain NaN or inf")
    L = max(a.shape[0] for a in arrs)
    out = np.zeros((len(arrs), max(L, 1), d))
    for i, a in enumerate(arrs):
        if pad == "append":
            out[i, : a.shape[0]] = a
        else:
            out[i, L - a.shape[0]:] = a
    return out


def continuous_trace_distances(traces: Sequence[np.ndarray], pad: str = "append") -> np.ndarray:
    """D[i, j] = sum_t || a_i(t) - a_j(t) || over zero-padded traces (Eq 3.1)."""
    X = pad_traces(traces, pad)
    n, L, _ = X.shape
    D = np.zeros((n, n))
    for t in range(L):
        step = X[:, t, :]
        if not step.any():
            continue
        D += cdist(step, step)
    np.fill_diagonal(D, 0.0)
    return D


def edit_trace_distances(traces: Sequence[Sequence[int]], substitution_cost: int = 1) -> np.ndarray:
    """Pairwise edit distance between discrete action sequences (compiled, all cores)."""
    from rapidfuzz.distance import Levenshtein
    from rapidfuzz.process import cdist as rf_cdist

    if substitution_cost < 1:
        raise ValueError("substitution_cost must be >= 1")
    seqs = [[int(a) for a in t] for t in traces]
    if not seqs:
        raise ValueError("no traces")
    D = rf_cdist(seqs, seqs, scorer=Levenshtein.distance, dtype=np.int32, workers=-1,
                 scorer_kwargs={"weights": (1, 1, int(substitution_cost))})
    return D.astype(np.float64)


def trace_distances(traces: Sequence, kind: str = "continuous", pad: str = "append",
                    substitution_cost: int = 1) -> np.ndarray:
    """Pairwise trace distances: kind "continuous" (padded sum) or "edit" (discrete actions)."""
    if kind == "continuous":
        return continuous_trace_distances(traces, pad)
    if kind == "edit":
        return edit_trace_distances(traces, substitution_cost)
    raise ValueError(f"kind must be 'continuous' or 'edit', not {kind!r}")
