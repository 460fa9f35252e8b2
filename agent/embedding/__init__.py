"""Sensorimotor embedding maths: pure numpy/scipy functions."""

from agent.embedding.classical_mds import MDSResult, classical_mds, double_centre
from agent.embedding.procrustes import ProcrustesResult, procrustes, procrustes_error
from agent.embedding.trace_distances import (
    continuous_trace_distances, edit_trace_distances, pad_traces, trace_distances,
)

__all__ = [
    "MDSResult", "classical_mds", "double_centre", "ProcrustesResult", "procrustes",
    "procrustes_error", "continuous_trace_distances", "edit_trace_distances", "pad_traces",
    "trace_distances",
]
