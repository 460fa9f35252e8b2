"""Procrustes error against ground truth (Eq 3.3-3.10): the disparity after removing translation,
scale and rotation/reflection; equal to `scipy.spatial.procrustes`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ProcrustesResult:
    """Procrustes alignment of an embedding onto truth: the `disparity` (sum of squared
    differences after alignment, in [0, 1]), standardised `truth` and the `aligned` embedding.
    """

    disparity: float
    truth: np.ndarray  # standardised truth (centred, unit Frobenius norm)
    aligned: np.ndarray  # embedding after the best similarity transform onto `truth`


def _standardise(X: np.ndarray, name: str) -> np.ndarray:
    X = X - X.mean(axis=0)
    norm = np.linalg.norm(X)
    if norm == 0:
        raise ValueError(f"{name} has all points identical: Procrustes error is undefined")
    return X / norm


def procrustes(truth: np.ndarray, embedding: np.ndarray) -> ProcrustesResult:
    """Align `embedding` onto `truth` by translation, scale and rotation/reflection.

    Rows are corresponding points. Columns are zero-padded to the same count, so a 1-D embedding
    can be compared with 2-D truth. Matches `scipy.spatial.procrustes`.

    Parameters
    ----------
    truth : np.ndarray
        Ground-truth positions, [n, d] (or [n]); used for evaluation only.
    embedding : np.ndarray
        Learned coordinates of the same n points, [n, k] (or [n]).

    Returns
    -------
    ProcrustesResult

    Raises
    ------
    ValueError
        If the row counts differ, n < 2, or either set has all points identical.
    """
    A = np.asarray(truth, dtype=np.float64)
    B = np.asarray(embedding, dtype=np.float64)
    A = A.reshape(-1, 1) if A.ndim == 1 else A
    B = B.reshape(-1, 1) if B.ndim == 1 else B
    if A.ndim != 2 or B.ndim != 2 or A.shape[0] != B.shape[0]:
        raise ValueError(f"truth and embedding need the same number of rows: {A.shape} vs {B.shape}")
    if A.shape[0] < 2:
        raise ValueError("Procrustes needs at least 2 points")
    d = max(A.shape[1], B.shape[1])
    A = np.pad(A, ((0, 0), (0, d - A.shape[1])))
    B = np.pad(B, ((0, 0), (0, d - B.shape[1])))
    A = _standardise(A, "truth")
    B = _standardise(B, "embedding")
    U, s, Vt = np.linalg.svd(B.T @ A)
    R = U @ Vt
    aligned = (B @ R) * s.sum()
    return ProcrustesResult(float(np.square(A - aligned).sum()), A, aligned)


def procrustes_error(truth: np.ndarray, embedding: np.ndarray) -> float:
    """Procrustes disparity of `embedding` against `truth` (Eq 3.3-3.10): 0 for a perfect shape.

    Parameters
    ----------
    truth : np.ndarray
        Ground-truth positions [n, d].
    embedding : np.ndarray
        Coordinates [n, k] of the same points, in the same order.

    Returns
    -------
    float
        Sum of squared differences after the best similarity transform, in [0, 1].

    Examples
    --------
    Scale, rotation and translation do not count::

        procrustes_error(truth, 3.0 * truth @ rotation + 1.0)  # ~0.0: the same shape
    """
    return procrustes(truth, embedding).disparity


@dataclass(frozen=True)
class SimilarityTransform:
    """x -> scale * x @ rotation + translation."""

    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, X: np.ndarray) -> np.ndarray:
        """Map the rows of `X` through the transform."""
        return self.scale * np.asarray(X, dtype=np.float64) @ self.rotation + self.translation


def fit_similarity(target: np.ndarray, source: np.ndarray) -> SimilarityTransform:
    """The similarity transform (scale, rotation or reflection, translation) mapping the rows of
    `source` onto the corresponding rows of `target` with least squared error: how a new embedding
    is put in the coordinates of an older one of the same start states."""
    A = np.asarray(target, dtype=np.float64)
    B = np.asarray(source, dtype=np.float64)
    A = A.reshape(-1, 1) if A.ndim == 1 else A
    B = B.reshape(-1, 1) if B.ndim == 1 else B
    if A.shape != B.shape or A.shape[0] < 2:
        raise ValueError(f"need two equal shapes with >= 2 rows, got {A.shape} and {B.shape}")
    mu_a, mu_b = A.mean(axis=0), B.mean(axis=0)
    A0, B0 = A - mu_a, B - mu_b
    norm = float(np.square(B0).sum())
    if norm == 0:
        raise ValueError("source has all points identical")
    U, s, Vt = np.linalg.svd(B0.T @ A0)
    R = U @ Vt
    scale = float(s.sum() / norm)
    return SimilarityTransform(scale, R, mu_a - scale * mu_b @ R)
