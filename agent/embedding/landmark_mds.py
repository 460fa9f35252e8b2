"""Landmark MDS (de Silva & Tenenbaum 2004) for many start states.

Pick m landmarks by max-min distance (seeded; among a random candidate subset of 10 m points, so
selection costs O(m^2) comparisons), embed them with classical MDS, and place every point by the
landmark model (Gower's formula on its distances to the landmarks), computed in one parallel pass.
Cost: O(n m) trace comparisons and an m x m eigenproblem instead of O(n^2) and n x n.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sensorimotor.agent.embedding.classical_mds import MDSModel, classical_mds

DistancesTo = Callable[[np.ndarray], np.ndarray]  # landmark indices [m] -> distances [n, m]


@dataclass(frozen=True)
class LandmarkResult:
    """The result of `landmark_mds`: coordinates of all n points, the landmark spectrum, the
    landmark indices and the model that places new points from their landmark distances.
    """

    coordinates: np.ndarray  # [n, k]
    eigenvalues: np.ndarray  # spectrum of the landmark embedding
    landmarks: np.ndarray  # indices of the landmarks
    model: MDSModel  # places any new point from its distances to the landmarks


def maxmin_landmarks(n: int, m: int, distances_to: DistancesTo, seed: int = 0) -> np.ndarray:
    """m point indices chosen greedily far apart (the first one at random, seeded)."""
    rng = np.random.default_rng(seed)
    chosen = [int(rng.integers(n))]
    nearest = distances_to(np.array(chosen))[:, 0].astype(np.float64)
    while len(chosen) < min(m, n):
        nearest[chosen] = -1.0
        nxt = int(np.argmax(nearest))
        if nearest[nxt] <= 0:
            break  # the remaining points coincide with landmarks
        chosen.append(nxt)
        np.minimum(nearest, distances_to(np.array([nxt]))[:, 0], out=nearest)
    return np.array(chosen)


def landmark_mds(
    n: int,
    distances_to: DistancesTo,
    k: int = 2,
    n_landmarks: int = 300,
    seed: int = 0,
    select: str = "maxmin",
    candidate_distances_to: Callable[[np.ndarray], DistancesTo] | None = None,
) -> LandmarkResult:
    """Landmark MDS (de Silva & Tenenbaum 2004): embed m landmarks, place all n points.

    Parameters
    ----------
    n : int
        Number of points (>= 2).
    distances_to : callable
        `distances_to(idx)` -> [n, len(idx)]: distances of every point to the points `idx`.
    k : int, default 2
        Embedding dimensions.
    n_landmarks : int, default 300
        Landmarks m (at least k + 1, at most n).
    seed : int, default 0
        Seed of the landmark choice.
    select : {"maxmin", "random"}, default "maxmin"
        Greedy far-apart landmarks, or a uniform random subset.
    candidate_distances_to : callable, optional
        `candidate_distances_to(pool)` -> a `distances_to` over the points of `pool` only: max-min
        selection then runs on a random pool of 10 m points instead of all n.

    Returns
    -------
    LandmarkResult
    """
    if n < 2:
        raise ValueError("need at least 2 points")
    m = min(n, max(k + 1, n_landmarks))
    if select == "maxmin":
        rng = np.random.default_rng(seed)
        if candidate_distances_to is not None and 10 * m < n:
            pool = np.sort(rng.choice(n, 10 * m, replace=False))
            L = pool[maxmin_landmarks(pool.size, m, candidate_distances_to(pool), seed)]
        else:
            L = maxmin_landmarks(n, m, distances_to, seed)
    elif select == "random":
        L = np.sort(np.random.default_rng(seed).choice(n, m, replace=False))
    else:
        raise ValueError("select must be 'maxmin' or 'random'")
    D_nL = distances_to(L)
    res = classical_mds(np.asarray(D_nL[L], dtype=np.float64), k, method="full" if len(L) <= 1500 else "topk")
    Y = res.model.transform(D_nL)
    return LandmarkResult(Y, res.eigenvalues, L, res.model)


def landmark_trace_embedding(
    traces,
    k: int = 2,
    n_landmarks: int = 300,
    kind: str = "continuous",
    pad: str = "append",
    substitution_cost: int = 1,
    seed: int = 0,
) -> LandmarkResult:
    """Landmark MDS of action traces; the model then places new traces without re-embedding
    (`trace_cross_distances(new, [traces[i] for i in result.landmarks])` -> `result.model.transform`)."""
    from sensorimotor.agent.embedding.trace_distances import PreparedTraces

    prepared = PreparedTraces(traces, kind, pad, substitution_cost)
    return landmark_mds(
        len(traces),
        prepared.distances_to,
        k,
        n_landmarks,
        seed,
        candidate_distances_to=lambda pool: prepared.subset(pool).distances_to,
    )
