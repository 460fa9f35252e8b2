"""The field's scores of an embedding against ground truth, beside the dissertation's Procrustes error.

- Trustworthiness (Venna & Kaski 2001; `sklearn.manifold.trustworthiness`): are the embedding's
  k nearest neighbours of a point also near it in truth? 1 = every embedded neighbour is a true one.
- Continuity: the same with the spaces swapped: are the true neighbours kept near in the embedding?
- Metric and topological dissimilarity (Laflaquière et al. 2019, their `unsupervised-spatial-predictor`
  evaluator): truth is mapped into the embedding by an affine least-squares fit, then
  ``mean(|d_emb - d_fit| / max d_emb * w)`` over all pairs, with ``w = 1`` (metric) or
  ``w = exp(-10 d_fit / max d_fit)`` (topological: near pairs weigh most). 0 = the embedding is an
  affine image of the truth.

All four cost O(n^2) memory and O(n^2 log n) time; above `max_points` they are computed on a
deterministic subsample (`default_rng(0)`), and the result says how many points were scored.
Pure numpy: the agent's maths runs without scikit-learn (a test checks equality with sklearn).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import pdist, squareform

DEFAULT_NEIGHBOURS = 5  # sklearn's default n_neighbors
DEFAULT_MAX_POINTS = 1000  # above this, scores are computed on a fixed subsample of this size
TOPOLOGICAL_WEIGHT = 10.0  # Laflaquière et al.: exp(-10 d / max d)


@dataclass(frozen=True)
class FieldScores:
    """Trustworthiness, continuity and the two dissimilarities of one embedding.

    `n_neighbors` is the k the neighbourhood scores used; `n_points` how many points were scored
    (fewer than the embedding's rows when it was subsampled)."""

    trustworthiness: float
    continuity: float
    metric_dissimilarity: float
    topological_dissimilarity: float
    n_neighbors: int
    n_points: int


def _as_2d(X: np.ndarray, name: str) -> np.ndarray:
    A = np.asarray(X, dtype=np.float64)
    A = A.reshape(-1, 1) if A.ndim == 1 else A
    if A.ndim != 2:
        raise ValueError(f"{name} must be [n, d], got shape {A.shape}")
    if not np.isfinite(A).all():
        raise ValueError(f"{name} has NaN or inf")
    return A


def pairwise_distances(X: np.ndarray) -> np.ndarray:
    """Euclidean distance matrix [n, n] of the rows of X."""
    return squareform(pdist(_as_2d(X, "X")))


def max_neighbours(n: int, k: int = DEFAULT_NEIGHBOURS) -> int:
    """The k the neighbourhood scores use for n points: `k`, lowered below n / 2 as sklearn requires
    (0 when n < 3: no neighbourhood score exists)."""
    return max(0, min(int(k), (n - 1) // 2))


def _trust(D_ref: np.ndarray, D_emb: np.ndarray, k: int) -> float:
    """Trustworthiness of the neighbourhoods of `D_emb` against the ranks of `D_ref`.

    Rank r(i, j) of j among i's neighbours in the reference space (1 = nearest). Ties in the
    reference count with the lowest rank of the tie (a point as near as the k-th neighbour is a
    neighbour), so a perfect map of a regular grid scores 1; without ties this is sklearn's value."""
    n = D_ref.shape[0]
    if k < 1 or k >= n / 2:
        raise ValueError(f"n_neighbors must be in [1, n/2) for n = {n}, got {k}")
    scale = max(float(D_ref.max()), 1e-300)
    tol = 1e-9 * scale
    ref = D_ref.copy()  # copies: the diagonal (a point itself) is never a neighbour
    np.fill_diagonal(ref, np.inf)
    emb = D_emb.copy()
    np.fill_diagonal(emb, np.inf)
    # the k nearest in the embedding (which of several tied at the k-th distance: argpartition's choice)
    nn = np.argpartition(emb, k - 1, axis=1)[:, :k]
    d = ref[np.arange(n)[:, None], nn] - tol
    # rank of j = 1 + how many points are strictly nearer to i than j in the reference space
    ranks = np.empty((n, k), dtype=np.int64)
    for lo in range(0, n, 256):  # in blocks: [block, k, n] booleans stay small
        blk = slice(lo, lo + 256)
        ranks[blk] = (ref[blk, None, :] < d[blk, :, None]).sum(axis=2) + 1
    excess = ranks - k
    total = float(excess[excess > 0].sum())
    return 1.0 - total * 2.0 / (n * k * (2.0 * n - 3.0 * k - 1.0))


def trustworthiness(truth: np.ndarray, embedding: np.ndarray, n_neighbors: int = DEFAULT_NEIGHBOURS) -> float:
    """Trustworthiness in [0, 1] of `embedding` rows against `truth` rows (same order).

    Equals ``sklearn.manifold.trustworthiness(truth, embedding, n_neighbors=k)`` when no two
    distances tie; see `_trust` for ties. Raises ValueError unless 1 <= k < n / 2."""
    A, B = _as_2d(truth, "truth"), _as_2d(embedding, "embedding")
    if A.shape[0] != B.shape[0]:
        raise ValueError(f"truth and embedding need the same rows: {A.shape[0]} vs {B.shape[0]}")
    return _trust(pairwise_distances(A), pairwise_distances(B), int(n_neighbors))


def continuity(truth: np.ndarray, embedding: np.ndarray, n_neighbors: int = DEFAULT_NEIGHBOURS) -> float:
    """Continuity in [0, 1]: trustworthiness with the roles swapped (true neighbours stay near)."""
    return trustworthiness(embedding, truth, n_neighbors)


def affine_fit(truth: np.ndarray, embedding: np.ndarray) -> np.ndarray:
    """Truth mapped into the embedding's space by the least-squares affine map (the linear regression
    with intercept of Laflaquière et al.): rows are the fitted points [n, dims of embedding]."""
    A, B = _as_2d(truth, "truth"), _as_2d(embedding, "embedding")
    X = np.hstack([A, np.ones((A.shape[0], 1))])
    W, *_ = np.linalg.lstsq(X, B, rcond=None)
    return X @ W


def _dissimilarity(d_emb: np.ndarray, d_fit: np.ndarray, weight: float) -> float:
    top = float(d_emb.max(initial=0.0))
    if top <= 0:
        raise ValueError("every embedded point is the same: the dissimilarity is undefined")
    fit_top = float(d_fit.max(initial=0.0))
    w = np.exp(-weight * d_fit / fit_top) if fit_top > 0 else np.ones_like(d_fit)
    return float(np.mean(np.abs(d_emb - d_fit) / top * w))


def dissimilarity(truth: np.ndarray, embedding: np.ndarray, weight: float = 0.0) -> float:
    """Laflaquière's dissimilarity: mean over pairs of |d_emb - d_fit| / max d_emb, each weighted by
    exp(-weight * d_fit / max d_fit), where d_fit are distances of the affinely fitted truth.
    weight 0: the metric dissimilarity; 10: the topological one. Raises ValueError when every
    embedded point is the same (no scale to normalise by)."""
    B = _as_2d(embedding, "embedding")
    return _dissimilarity(pdist(B), pdist(affine_fit(truth, B)), weight)


def subsample(n: int, max_points: int = DEFAULT_MAX_POINTS) -> np.ndarray:
    """The rows scored for n points: all of them, or a fixed sorted random subset of `max_points`
    (generator seeded 0, so the same n always gives the same rows)."""
    if n <= max_points:
        return np.arange(n)
    return np.sort(np.random.default_rng(0).choice(n, size=max_points, replace=False))


def field_scores(
    truth: np.ndarray,
    embedding: np.ndarray,
    n_neighbors: int = DEFAULT_NEIGHBOURS,
    max_points: int = DEFAULT_MAX_POINTS,
) -> FieldScores | None:
    """All four scores of `embedding` against `truth` (rows correspond), or None when they are
    undefined (fewer than 3 points, or all embedded or all true points the same).

    Above `max_points` rows the scores use the fixed subsample of `subsample`; k is lowered for
    small n (`max_neighbours`)."""
    A, B = _as_2d(truth, "truth"), _as_2d(embedding, "embedding")
    if A.shape[0] != B.shape[0]:
        raise ValueError(f"truth and embedding need the same rows: {A.shape[0]} vs {B.shape[0]}")
    rows = subsample(A.shape[0], max_points)
    A, B = A[rows], B[rows]
    n = A.shape[0]
    k = max_neighbours(n, n_neighbors)
    if k < 1:
        return None
    dA, dB = pdist(A), pdist(B)
    if dA.max() <= 0 or dB.max() <= 0:
        return None
    DA, DB = squareform(dA), squareform(dB)
    d_fit = pdist(affine_fit(A, B))
    return FieldScores(
        trustworthiness=_trust(DA, DB, k),
        continuity=_trust(DB, DA, k),
        metric_dissimilarity=_dissimilarity(dB, d_fit, 0.0),
        topological_dissimilarity=_dissimilarity(dB, d_fit, TOPOLOGICAL_WEIGHT),
        n_neighbors=k,
        n_points=n,
    )
