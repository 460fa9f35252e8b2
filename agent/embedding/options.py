"""Option discovery with sensorimotor embedding (ch. 9.6, Fig 9.3).

Split the action traces of a trained policy into fixed-length segments, embed the segments (edit
distance between segments, classical MDS), cluster the embedded points (k-means, scikit-learn),
and take each cluster's mode - its most frequent segment, a real action sequence (the pre-image of
the cluster mode) - as an option: an open-loop macro-action the next agent can choose.
`random_options` gives the control: the same number of uniformly random sequences.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sensorimotor.agent.embedding.classical_mds import classical_mds
from sensorimotor.agent.embedding.trace_distances import trace_distances

Option = tuple[int, ...]


def segments(traces: Sequence[Sequence[int]], length: int = 5) -> list[Option]:
    """Consecutive non-overlapping segments of `length` actions of every trace (remainders dropped)."""
    if length < 1:
        raise ValueError("segment length must be >= 1")
    out: list[Option] = []
    for t in traces:
        t = [int(a) for a in t]
        out += [tuple(t[i : i + length]) for i in range(0, len(t) - length + 1, length)]
    return out


@dataclass(frozen=True)
class DiscoveredOptions:
    """The segments, their embedding and cluster labels, and the options (one mode per cluster,
    in decreasing cluster size; duplicates dropped)."""

    segments: list[Option]
    coordinates: np.ndarray  # [n_segments, dims]
    labels: np.ndarray  # [n_segments] cluster of each segment
    options: list[Option]


def discover_options(
    traces: Sequence[Sequence[int]], n_options: int = 4, length: int = 5, dims: int = 3, seed: int = 0
) -> DiscoveredOptions:
    """Options from the traces of a trained policy (ch. 9.6): segment, embed, cluster, take modes.

    Parameters
    ----------
    traces : sequence of sequences of int
        Discrete action traces of the trained policy (e.g. from random start states).
    n_options : int, default 4
        Number of clusters, hence at most this many options.
    length : int, default 5
        Segment (and option) length, in actions.
    dims : int, default 3
        Embedding dimensions of the segments.
    seed : int, default 0
        Seeds k-means.

    Returns
    -------
    DiscoveredOptions
    """
    from sklearn.cluster import KMeans

    segs = segments(traces, length)
    distinct = len(set(segs))
    if distinct < 1:
        raise ValueError(f"no trace is {length} actions long: nothing to discover options from")
    k = min(n_options, distinct)
    D = trace_distances(segs, kind="edit", substitution_cost=1)
    X = classical_mds(D, min(dims, max(1, len(segs) - 1))).coordinates
    labels = KMeans(k, n_init=10, random_state=seed).fit_predict(X) if k > 1 else np.zeros(len(segs), dtype=int)
    sizes = Counter(labels.tolist())
    options: list[Option] = []
    for c, _ in sizes.most_common():
        members = Counter(s for s, lab in zip(segs, labels, strict=True) if lab == c)
        mode = members.most_common(1)[0][0]
        if mode not in options:
            options.append(mode)
    return DiscoveredOptions(segs, X, np.asarray(labels), options)


def random_options(n_actions: int, n_options: int, length: int = 5, seed: int = 0) -> list[Option]:
    """`n_options` uniformly random action sequences of `length`: the control for discovered options."""
    rng = np.random.default_rng(seed)
    return [tuple(int(a) for a in rng.integers(n_actions, size=length)) for _ in range(n_options)]
