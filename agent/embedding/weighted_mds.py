"""Weighted metric MDS (SMACOF with weights), initialised from classical MDS: an embedding that
trusts short distances more than long ones.

Why: classical MDS fits every distance equally (in squared terms, so the longest dominate). Where
the distances are not Euclidean - a map of the ways round a wall, a lake's holes - the long ones
are the most distorted, and they bend the whole map. Weighting each pair by d^-power (power 2:
Sammon-like, each pair's error relative to its distance) lets the near pairs, which a trace metric
measures best, place the points. Minimises sum_{i<j} w_ij (|x_i - x_j| - d_ij)^2 by Guttman
transforms (de Leeuw's majorisation: the stress never rises), from the classical MDS coordinates.
scikit-learn's `smacof` has no weights, hence this; with equal weights it is the same algorithm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import cdist

from sensorimotor.agent.embedding.classical_mds import check_distances, classical_mds

#: the default weight exponent: w_ij = d_ij^-2 (Sammon-like)
POWER = 2.0


@dataclass(frozen=True)
class WeightedMDSResult:
    """The coordinates, the weighted stress before (classical MDS) and after, and iterations run."""

    coordinates: np.ndarray  # [n, k]
    stress: float  # sum_{i<j} w_ij (|x_i - x_j| - d_ij)^2, normalised by sum_{i<j} w_ij d_ij^2
    initial_stress: float  # the same, of the classical MDS start
    iterations: int


def distance_weights(D: np.ndarray, power: float = POWER) -> np.ndarray:
    """w_ij = d_ij^-power for d_ij > 0, else 0 (a pair at distance 0 adds no constraint)."""
    D = np.asarray(D, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.where(D > 0, np.power(np.where(D > 0, D, 1.0), -float(power)), 0.0)


def _stress(X: np.ndarray, D: np.ndarray, W: np.ndarray) -> tuple[float, np.ndarray]:
    d = cdist(X, X)
    r = d - D
    np.square(r, out=r)
    r *= W
    return float(r.sum() / 2), d


def weighted_mds(
    D: np.ndarray,
    k: int = 2,
    weights: np.ndarray | None = None,
    power: float = POWER,
    init: np.ndarray | None = None,
    max_iter: int = 300,
    eps: float = 1e-7,
) -> WeightedMDSResult:
    """Weighted SMACOF of a distance matrix.

    Parameters
    ----------
    D : np.ndarray
        Square [n, n] distances (symmetric, zero diagonal, finite).
    k : int, default 2
        Embedding dimensions, 1 <= k <= n.
    weights : np.ndarray, optional
        Symmetric [n, n] non-negative pair weights; default `distance_weights(D, power)`.
    power : float, default 2
        The weight exponent when `weights` is not given (0: equal weights, plain SMACOF).
    init : np.ndarray, optional
        [n, k] start; default classical MDS of D (deterministic: equal inputs, equal output).
    max_iter : int, default 300
        Guttman transforms at most.
    eps : float, default 1e-7
        Stop when the stress falls by less than this fraction of itself.

    Returns
    -------
    WeightedMDSResult

    Raises
    ------
    ValueError
        If `D` is not square or not finite, `k` is out of range, or shapes disagree.
    """
    D = check_distances(np.asarray(D, dtype=np.float64), k)
    n = D.shape[0]
    W = distance_weights(D, power) if weights is None else np.array(weights, dtype=np.float64)
    if W.shape != D.shape or (W < 0).any():
        raise ValueError(f"weights must be non-negative and of shape {D.shape}")
    np.fill_diagonal(W, 0.0)
    X = classical_mds(D, k).coordinates if init is None else np.array(init, dtype=np.float64)
    if X.shape != (n, k):
        raise ValueError(f"init must be of shape {(n, k)}, got {X.shape}")
    norm = max(float((W * np.square(D)).sum() / 2), 1e-300)
    if n < 2 or W.sum() == 0:
        s = _stress(X, D, W)[0] / norm
        return WeightedMDSResult(X, s, s, 0)
    V = np.diag(W.sum(axis=1)) - W
    Vp = np.linalg.pinv(V + 1.0 / n) - 1.0 / n  # Moore-Penrose inverse of V (its null space: the ones)
    WD = W * D
    s, d = _stress(X, D, W)
    s0, it = s, 0
    while it < max_iter:
        it += 1
        d[d == 0] = np.inf  # coincident points: no pull (B_ij = 0)
        B = WD / d
        B *= -1.0
        np.fill_diagonal(B, 0.0)
        np.fill_diagonal(B, -B.sum(axis=1))
        X = Vp @ (B @ X)
        s_new, d = _stress(X, D, W)
        done = s - s_new <= eps * s
        s = s_new
        if done:
            break
    return WeightedMDSResult(coordinates=X, stress=s / norm, initial_stress=s0 / norm, iterations=it)


__all__ = ["POWER", "WeightedMDSResult", "distance_weights", "weighted_mds"]
