"""Sensorimotor embedding maths: pure functions (numpy/scipy; numba and rapidfuzz accelerate)."""

from sensorimotor.agent.embedding.classical_mds import MDSModel, MDSResult, classical_mds, double_centre
from sensorimotor.agent.embedding.landmark_mds import (
    LandmarkResult,
    landmark_mds,
    landmark_trace_embedding,
    maxmin_landmarks,
)
from sensorimotor.agent.embedding.procrustes import (
    ProcrustesResult,
    SimilarityTransform,
    fit_similarity,
    procrustes,
    procrustes_error,
)
from sensorimotor.agent.embedding.trace_distances import (
    PreparedTraces,
    continuous_trace_distances,
    edit_trace_distances,
    pad_traces,
    trace_cross_distances,
    trace_distances,
    update_trace_distances,
)

__all__ = [
    "MDSModel",
    "MDSResult",
    "classical_mds",
    "double_centre",
    "LandmarkResult",
    "landmark_mds",
    "landmark_trace_embedding",
    "maxmin_landmarks",
    "ProcrustesResult",
    "SimilarityTransform",
    "fit_similarity",
    "procrustes",
    "procrustes_error",
    "PreparedTraces",
    "continuous_trace_distances",
    "edit_trace_distances",
    "pad_traces",
    "trace_cross_distances",
    "trace_distances",
    "update_trace_distances",
]
