"""Scoring embeddings against ground truth. Truth is for evaluation only: it reaches the link,
never a program or learner."""

from __future__ import annotations

import numpy as np

from sensorimotor.agent.embedding import procrustes_error
from sensorimotor.agent.embedding.scores import field_scores
from sensorimotor.agent.programs.base import EmbeddingOutput
from sensorimotor.protocol.messages import EmbeddingScores, Truth


def _rows(output: EmbeddingOutput, truth: Truth | None) -> np.ndarray | None:
    """The truth rows of the output's ids, or None when truth is unknown or does not cover them."""
    if truth is None or "positions" not in truth.tensors:
        return None
    pos = np.asarray(truth.tensors["positions"], dtype=np.float64)
    ids = np.asarray(output.ids, dtype=np.int64)
    if ids.size < 2 or ids.max(initial=-1) >= pos.shape[0] or ids.min(initial=0) < 0:
        return None
    return pos[ids]


def evaluate_embedding(output: EmbeddingOutput, truth: Truth | None) -> dict[str, float]:
    """Scores of the output's rows against the truth rows with the same ids: `procrustes_error`
    always (when truth is known), and `e_geometry` (Eq 4.6: mean distance without alignment) for
    outputs whose coordinates are in the truth's units."""
    true = _rows(output, truth)
    if true is None:
        return {}
    coords = np.asarray(output.coordinates, dtype=np.float64)
    if coords.ndim == 2 and np.ptp(coords, axis=0).max(initial=0.0) <= 1e-12 * max(
        1.0, float(np.abs(coords).max(initial=0.0))
    ):
        # a map that puts every state at one point (e.g. every trace the same) says nothing: the
        # worst Procrustes error, 1, rather than an undefined one
        return {"procrustes_error": 1.0}
    out = {"procrustes_error": procrustes_error(true, output.coordinates)}
    if output.absolute and true.shape[1] == output.coordinates.shape[1]:
        out["e_geometry"] = float(np.linalg.norm(output.coordinates - true, axis=1).mean())
    return out


def embedding_scores(output: EmbeddingOutput, truth: Truth | None) -> EmbeddingScores | None:
    """Trustworthiness, continuity and Laflaquière's dissimilarities of the output against truth
    (`agent.embedding.scores.field_scores`: a fixed subsample above 1000 rows), or None without
    truth or when they are undefined (fewer than 3 points, all points the same)."""
    true = _rows(output, truth)
    if true is None:
        return None
    fs = field_scores(true, output.coordinates)
    if fs is None:
        return None
    return EmbeddingScores(
        fs.trustworthiness,
        fs.continuity,
        fs.metric_dissimilarity,
        fs.topological_dissimilarity,
        fs.n_neighbors,
        fs.n_points,
    )
