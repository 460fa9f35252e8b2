"""Classical (Torgerson) multidimensional scaling (Eq 2.16-2.23), with an out-of-sample model.

K = -1/2 J D^2 J; the top-k eigenvectors scaled by sqrt(eigenvalue) are the coordinates. Trace
distances need not be Euclidean, so K can have negative eigenvalues: method "full" (dense
eigendecomposition, small n) reports the whole spectrum; "topk" (Lanczos, scipy eigsh) computes only
the k largest and is what large n uses. With `overwrite=True` a float32 or float64 D is turned into
K in place: no hidden n x n copies.

The returned `model` places new points from their distances to the embedded ones (Gower's formula,
the same map landmark MDS uses): y = -1/2 Lambda^-1/2 V^T (delta^2 - mean_column(D^2)). For a point
already in the set it gives back exactly its coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh
from scipy.sparse.linalg import eigsh

FULL_BELOW = 600


@dataclass(frozen=True)
class MDSModel:
    """Out-of-sample map of a classical MDS embedding (Gower's formula).

    Places new points from their distances to the reference points without re-embedding; for a
    reference point it gives back exactly its coordinates.
    """

    basis: np.ndarray  # [n_ref, k]: V_k / sqrt(lambda_k) (0 where lambda <= 0)
    mean_sq: np.ndarray  # [n_ref]: column means of D^2 over the reference points

    def transform(self, d_ref: np.ndarray) -> np.ndarray:
        """Coordinates [m, k] of points whose distances to the reference points are d_ref [m, n_ref]."""
        d = np.asarray(d_ref, dtype=np.float64)
        d = d.reshape(1, -1) if d.ndim == 1 else d
        if d.shape[1] != self.mean_sq.size:
            raise ValueError(f"need distances to {self.mean_sq.size} reference points, got {d.shape[1]}")
        return -0.5 * (np.square(d) - self.mean_sq) @ self.basis


@dataclass(frozen=True)
class MDSResult:
    """The result of `classical_mds`: coordinates, spectrum, the method used and the
    out-of-sample `model`.
    """

    coordinates: np.ndarray  # [n, k]
    eigenvalues: np.ndarray  # descending; the full spectrum for method "full", the top k otherwise
    method: str
    model: MDSModel  # places new points from their distances to these ones

    @property
    def dims(self) -> int:
        """Number of embedding dimensions (columns of `coordinates`)."""
        return self.coordinates.shape[1]


def double_centre(D: np.ndarray, overwrite: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(K, column means of D^2): K = -1/2 J D^2 J, computed in D's own memory when `overwrite`."""
    K = D if overwrite else np.array(D, dtype=np.result_type(D.dtype, np.float32), copy=True)
    np.square(K, out=K)
    col = K.mean(axis=0, dtype=np.float64)
    grand = float(col.mean())
    K -= col.astype(K.dtype)[None, :]
    K -= col.astype(K.dtype)[:, None]  # D^2 is symmetric: row means = column means
    K += K.dtype.type(grand)
    K *= K.dtype.type(-0.5)
    return K, col


def check_distances(D: np.ndarray, k: int) -> np.ndarray:
    """`D` as an array (its dtype kept), refused unless it is a square, finite distance matrix with
    1 <= k <= n."""
    D = np.asarray(D)
    if D.ndim != 2 or D.shape[0] != D.shape[1]:
        raise ValueError(f"distance matrix must be square, got shape {D.shape}")
    n = D.shape[0]
    if not 1 <= k <= n:
        raise ValueError(f"k must be in 1..{n}, got {k}")
    if not np.isfinite(D).all():
        raise ValueError("distance matrix contains NaN or inf")
    return D


def classical_mds(D: np.ndarray, k: int = 2, method: str = "auto", overwrite: bool = False) -> MDSResult:
    """Classical (Torgerson) MDS of a distance matrix.

    Parameters
    ----------
    D : np.ndarray
        Square [n, n] matrix of pairwise distances (symmetric, zero diagonal, finite). Need not
        be Euclidean: negative eigenvalues are reported, not hidden.
    k : int, default 2
        Embedding dimensions, 1 <= k <= n.
    method : {"auto", "full", "topk"}, default "auto"
        "full": dense eigendecomposition, the whole spectrum; "topk": Lanczos for the k largest
        eigenvalues only; "auto" picks "full" for n <= FULL_BELOW (or k >= n - 1).
    overwrite : bool, default False
        Double-centre a float32/float64 `D` in place (no n x n copy); `D` is destroyed.

    Returns
    -------
    MDSResult
        `coordinates` [n, k] (eigenvector signs fixed, so equal inputs give equal bytes),
        `eigenvalues` in descending order, the `method` used, and `model` to place new points.

    Raises
    ------
    ValueError
        If `D` is not square, has NaN/inf, `k` is out of range or `method` unknown.

    Examples
    --------
    Embed points from their distances, then place a new point from its distances to them::

        X = np.random.default_rng(0).normal(size=(50, 2))
        res = classical_mds(cdist(X, X), k=2)  # res.coordinates: [50, 2]
        y = res.model.transform(cdist([[0.5, 0.5]], X))  # [1, 2], in the same frame
    """
    D = check_distances(D, k)
    n = D.shape[0]
    if method == "auto":
        method = "full" if n <= FULL_BELOW or k >= n - 1 else "topk"
    if method not in ("full", "topk"):
        raise ValueError(f"method must be auto, full or topk, not {method!r}")
    if D.dtype not in (np.float32, np.float64):
        D, overwrite = D.astype(np.float64), True
    K, col = double_centre(D, overwrite=overwrite)
    if method == "full":
        w, V = eigh(K.astype(np.float64, copy=False))
    else:
        v0 = np.full(n, 1.0 / np.sqrt(n)) + np.linspace(-1e-3, 1e-3, n)  # fixed start: same input, same output
        w, V = eigsh(K, k=k, which="LA", v0=v0.astype(K.dtype))
        w, V = w.astype(np.float64), V.astype(np.float64)
    order = np.argsort(w)[::-1]
    w, V = w[order], V[:, order]
    top = np.clip(w[:k], 0.0, None)
    X = V[:, :k] * np.sqrt(top)
    # Eigenvector signs are arbitrary: fix them so equal inputs give equal bytes everywhere.
    signs = np.sign(X[np.argmax(np.abs(X), axis=0), np.arange(k)])
    signs[signs == 0] = 1.0
    X = X * signs
    with np.errstate(divide="ignore"):
        inv = np.where(top > 0, 1.0 / np.sqrt(np.where(top > 0, top, 1.0)), 0.0)
    model = MDSModel(V[:, :k] * signs * inv, col)
    return MDSResult(coordinates=X, eigenvalues=w, method=method, model=model)
