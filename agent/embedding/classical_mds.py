"""Classical (Torgerson) multidimensional scaling (Eq 2.16-2.23).

K = -1/2 J D^2 J; the top-k eigenvectors scaled by sqrt(eigenvalue) are the coordinates. Trace
distances need not be Euclidean, so K can have negative eigenvalues: the full spectrum (method
"full") reports them; "topk" uses a Lanczos eigensolver for large n.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh
from scipy.sparse.linalg import eigsh

FULL_BELOW = 600


@dataclass(frozen=True)
class MDSResult:
    coordinates: np.ndarray  # [n, k]
    eigenvalues: np.ndarray  # descending; the full spectrum for method "full", the top k otherwise
    method: str

    @property
    def dims(self) -> int:
        return self.coordinates.shape[1]


def double_centre(D: np.ndarray) -> np.ndarray:
    """K = -1/2 J D^2 J without forming J."""
    D2 = np.square(np.asarray(D, dtype=np.float64))
    row = D2.mean(axis=1, keepdims=True)
    return -0.5 * (D2 - row - row.T + D2.mean())


def classical_mds(D: np.ndarray, k: int = 2, method: str = "auto") -> MDSResult:
    D = np.asarray(D)
    if D.ndim != 2 or D.shape[0] != D.shape[1]:
        raise ValueError(f"distance matrix must be square, got shape {D.shape}")
    n = D.shape[0]
    if not 1 <= k <= n:
        raise ValueError(f"k must be in 1..{n}, got {k}")
    if not np.isfinite(D).all():
        raise ValueError("distance matrix contains NaN or inf")
    if method == "auto":
        method = "full" if n <= FULL_BELOW or k >= n - 1 else "topk"
    K = double_centre(D)
    if method == "full":
        w, V = eigh(K)
        order = np.argsort(w)[::-1]
        w, V = w[order], V[:, order]
    elif method == "topk":
        w, V = eigsh(K, k=k, which="LA")
        order = np.argsort(w)[::-1]
        w, V = w[order], V[:, order]
    else:
        raise ValueError(f"method must be auto, full or topk, not {method!r}")
    top = np.clip(w[:k], 0.0, None)
    X = V[:, :k] * np.sqrt(top)
    # Eigenvector signs are arbitrary: fix them so equal inputs give equal bytes everywhere.
    signs = np.sign(X[np.argmax(np.abs(X), axis=0), np.arange(k)])
    signs[signs == 0] = 1.0
    return MDSResult(coordinates=X * signs, eigenvalues=w, method=method)
