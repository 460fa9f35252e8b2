"""Policy maps (ch. 9.6, Fig 9.2): sensorimotor embedding as a picture of what a policy does.

The action traces of a trained policy from many start states are compared (edit distance for
discrete actions, the padded-sum distance for continuous ones), embedded by classical MDS, and the
embedded points clustered (k-means or Ward's agglomerative clustering, scikit-learn). With
`n_clusters=None` the count is chosen by the silhouette score over 2..`max_clusters`. For the
mountain car the clusters separate failures, direct climbs from lucky starts, and rocking.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sensorimotor.agent.embedding.classical_mds import classical_mds
from sensorimotor.agent.embedding.trace_distances import trace_distances

METHODS = ("kmeans", "ward")


@dataclass(frozen=True)
class PolicyMap:
    """Embedded traces of a policy with a cluster label per trace."""

    coordinates: np.ndarray  # [n, dims]
    eigenvalues: np.ndarray
    labels: np.ndarray  # [n] in 0..n_clusters-1, cluster 0 the largest
    silhouette: float  # of the chosen clustering (in the embedding)

    @property
    def n_clusters(self) -> int:
        """Number of clusters."""
        return int(self.labels.max()) + 1 if self.labels.size else 0


def cluster_points(X: np.ndarray, k: int, method: str = "kmeans", seed: int = 0) -> np.ndarray:
    """Labels of `k` clusters of the rows of `X`, renumbered so that cluster 0 is the largest."""
    from sklearn.cluster import AgglomerativeClustering, KMeans

    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, not {method!r}")
    if method == "kmeans":
        raw = KMeans(k, n_init=10, random_state=seed).fit_predict(X)
    else:
        raw = AgglomerativeClustering(n_clusters=k, linkage="ward").fit_predict(X)
    order = np.argsort(-np.bincount(raw, minlength=k), kind="stable")
    remap = np.empty(k, dtype=np.int64)
    remap[order] = np.arange(k)
    return remap[raw]


def policy_map(
    traces: Sequence,
    n_clusters: int | None = None,
    dims: int = 2,
    kind: str = "edit",
    substitution_cost: int = 2,
    method: str = "kmeans",
    max_clusters: int = 6,
    seed: int = 0,
) -> PolicyMap:
    """Embed the traces of a policy and cluster them (Fig 9.2).

    Parameters
    ----------
    traces : sequence
        One action trace per start state (discrete action indices for ``kind="edit"``).
    n_clusters : int or None, default None
        Number of clusters; None chooses 2..`max_clusters` by the silhouette score.
    dims : int, default 2
        Embedding dimensions (clusters are found in these coordinates).
    kind, substitution_cost :
        The trace distance (see `trace_distances`).
    method : {"kmeans", "ward"}, default "kmeans"
        Clustering of the embedded points.
    max_clusters : int, default 6
        Largest count tried when `n_clusters` is None.
    seed : int, default 0
        Seeds k-means.

    Returns
    -------
    PolicyMap
    """
    from sklearn.metrics import silhouette_score

    if len(traces) < 3:
        raise ValueError("a policy map needs at least 3 traces")
    D = trace_distances(traces, kind=kind, substitution_cost=substitution_cost)
    mds = classical_mds(D, dims)
    X = mds.coordinates
    distinct = len(np.unique(np.round(X, 9), axis=0))
    if n_clusters is not None:
        if n_clusters < 1:
            raise ValueError("n_clusters must be >= 1")
        ks = [min(n_clusters, distinct)]
    else:
        ks = list(range(2, min(max_clusters, distinct - 1) + 1)) or [1]
    best: tuple[float, np.ndarray] | None = None
    for k in ks:
        labels = cluster_points(X, k, method, seed) if k > 1 else np.zeros(len(X), dtype=np.int64)
        score = float(silhouette_score(X, labels)) if 1 < k < len(X) else 0.0
        if best is None or score > best[0]:
            best = (score, labels)
    assert best is not None
    return PolicyMap(X, mds.eigenvalues, best[1], best[0])
