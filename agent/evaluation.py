"""Scoring embeddings against ground truth. Truth is for evaluation only: it reaches the link,
never a program or learner."""

from __future__ import annotations

import numpy as np

from agent.embedding import procrustes_error
from agent.programs.base import EmbeddingOutput
from protocol.messages import Truth


def score_embedding(output: EmbeddingOutput, truth: Truth | None) -> float | None:
    """Procrustes error of the output's rows against the truth rows with the same ids."""
    if truth is None or "positions" not in truth.tensors:
        return None
    pos = np.asarray(truth.tensors["positions"], dtype=np.float64)
    ids = np.asarray(output.ids, dtype=np.int64)
    if ids.size < 2 or ids.max(initial=-1) >= pos.shape[0] or ids.min(initial=0) < 0:
        return None
    return procrustes_error(pos[ids], output.coordinates)
