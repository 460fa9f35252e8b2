"""The field's embedding scores in the reproduce tables: trustworthiness, continuity and Laflaquière's
metric / topological dissimilarities (agent/embedding/scores.py) beside each Procrustes error, as
JSON-ready dicts per run and as one table cell (mean ± 95 % CI over runs)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from sensorimotor.agent.embedding.scores import field_scores

#: the four scores, in table order
KEYS = ("trustworthiness", "continuity", "metric_dissimilarity", "topological_dissimilarity")
#: the column heading for a `cell`
HEADER = "trustworthiness / continuity / D_metric / D_topo"


def scores_of(embedding: Any) -> dict[str, float] | None:
    """An Embedding message's scores as a dict (None when it carries none: no truth)."""
    sc = getattr(embedding, "scores", None)
    return None if sc is None else {k: float(v) for k, v in dataclasses.asdict(sc).items()}


def score_points(truth: np.ndarray, coordinates: np.ndarray) -> dict[str, float] | None:
    """The four scores of coordinates made outside the link (peers, baselines), as a dict."""
    fs = field_scores(np.asarray(truth, dtype=np.float64), np.asarray(coordinates, dtype=np.float64))
    return None if fs is None else {k: float(v) for k, v in dataclasses.asdict(fs).items()}


def ci95(values: list[float]) -> tuple[float, float]:
    """Mean and the half-width of its 95 % t interval (0 for one value)."""
    from scipy import stats

    a = np.asarray(values, dtype=np.float64)
    if a.size < 2:
        return float(a.mean()), 0.0
    return float(a.mean()), float(stats.t.ppf(0.975, a.size - 1) * a.std(ddof=1) / np.sqrt(a.size))


def summary(rows: list[dict[str, float] | None]) -> dict[str, tuple[float, float]]:
    """Mean and 95 % CI half-width of each score over the runs that have scores ({} if none)."""
    have = [r for r in rows if r is not None]
    if not have:
        return {}
    return {k: ci95([r[k] for r in have]) for k in KEYS}


def cell(rows: list[dict[str, float] | None], digits: int = 3) -> str:
    """One table cell: ``T ± ci / C ± ci / D_metric ± ci / D_topo ± ci`` over the runs, or ``n/a``."""
    s = summary(rows)
    if not s:
        return "n/a"
    return " / ".join(f"{s[k][0]:.{digits}f} ± {s[k][1]:.{digits}f}" for k in KEYS)


def one(rows: list[dict[str, float] | None], key: str, digits: int = 3) -> str:
    """One score as ``mean ± ci`` over the runs, or ``n/a``."""
    s = summary(rows)
    return f"{s[key][0]:.{digits}f} ± {s[key][1]:.{digits}f}" if s else "n/a"
