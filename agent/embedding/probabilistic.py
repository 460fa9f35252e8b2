"""Probabilistic sensorimotor embedding (ch. 9.4): trace distances when a start state yields a
distribution of action traces (stochastic transitions or policies), not one trace.

The two estimators the text proposes:

1. `mode_traces`: sample several traces per start state and keep the most frequent one (the mode)
   as the start's canonical trace; then embed as usual.
2. `mean_pair_distances`: for each pair of start states, the mean distance over sampled pairs of
   their traces.

A third, a distance between the trace distributions themselves: `mean_trace_distances`, the padded
sum (Eq 3.1) between the starts' mean traces (per step, the frequency of each action among the
samples that reached the goal), over the first steps (the median length), before the traces mix. Its diagonal is the within-start spread, which the plain mean ignores (set to 0);
   `debias=True` also subtracts the average of the two starts' spreads from each pair (an
   estimate of the noise floor that an additive constant would otherwise add to every distance).

`sample_until_settled` chooses the number of samples per start: it adds batches of samples until the
distance estimate changes by less than `tol` (relative Frobenius norm) between batches.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from sensorimotor.agent.embedding.trace_distances import trace_cross_distances, trace_distances

Trace = tuple[int, ...]


def mode_trace(samples: Sequence[Sequence[int]]) -> Trace:
    """The most frequent trace among `samples` (ties: the shortest, then the first seen)."""
    if not samples:
        raise ValueError("no samples")
    seqs = [tuple(int(a) for a in s) for s in samples]
    counts = Counter(seqs)
    first = {s: i for i, s in reversed(list(enumerate(seqs)))}
    return min(counts, key=lambda s: (-counts[s], len(s), first[s]))


def mode_traces(samples: Sequence[Sequence[Sequence[int]]]) -> list[Trace]:
    """`mode_trace` of each start state's samples: estimator 1 of ch. 9.4."""
    return [mode_trace(s) for s in samples]


def mode_distances(samples: Sequence[Sequence[Sequence[int]]], substitution_cost: int = 2) -> np.ndarray:
    """Edit distances between the mode traces of the start states: [n, n]."""
    return trace_distances(mode_traces(samples), kind="edit", substitution_cost=substitution_cost)


def mean_pair_distances(
    samples: Sequence[Sequence[Sequence[int]]], substitution_cost: int = 2, debias: bool = False
) -> np.ndarray:
    """Estimator 2 of ch. 9.4: D[i, j] = mean edit distance over all pairs (one trace sampled
    from start i, one from start j); zero diagonal. With `debias`, the mean within-start distance
    of i and j (their spreads) is subtracted, half each, and the result clipped at 0."""
    if not samples or any(len(s) == 0 for s in samples):
        raise ValueError("every start state needs at least one sampled trace")
    flat = [list(t) for s in samples for t in s]
    owner = np.repeat(np.arange(len(samples)), [len(s) for s in samples])
    # all sampled traces against each other, then the block means
    Dall = trace_cross_distances(flat, flat, kind="edit", substitution_cost=substitution_cost)
    n = len(samples)
    one_hot = np.zeros((n, owner.size))
    one_hot[owner, np.arange(owner.size)] = 1.0
    counts = one_hot.sum(axis=1)
    sums = one_hot @ Dall @ one_hot.T
    D = sums / np.outer(counts, counts)
    spread = np.zeros(n)
    for i in range(n):
        k = counts[i]
        spread[i] = sums[i, i] / (k * (k - 1)) if k > 1 else 0.0  # mean over distinct pairs
    if debias:
        D = np.maximum(D - 0.5 * (spread[:, None] + spread[None, :]), 0.0)
    np.fill_diagonal(D, 0.0)
    return D


def mean_traces(
    samples: Sequence[Sequence[Sequence[int]]],
    n_actions: int,
    reached: Sequence[Sequence[bool]] | None = None,
    horizon: int | None = None,
) -> np.ndarray:
    """Each start's *mean trace*: at every step t, the fraction of its samples whose action t was
    each action (a sample that has ended contributes a zero action, as Eq 3.1 pads): [n, horizon,
    n_actions]. With `reached`, only the samples that reached the goal count (all of a start's when
    none did). `horizon` defaults to the median length of the samples counted."""
    kept = []
    for i, s in enumerate(samples):
        ok = [list(t) for t, r in zip(s, reached[i], strict=True) if r] if reached is not None else []
        kept.append(ok or [list(t) for t in s])
    if not kept or any(len(s) == 0 for s in kept):
        raise ValueError("every start state needs at least one sampled trace")
    if horizon is None:
        horizon = max(1, int(np.median([len(t) for s in kept for t in s])))
    M = np.zeros((len(kept), horizon, n_actions))
    for i, s in enumerate(kept):
        for t in s:
            a = np.asarray(t[:horizon], dtype=np.int64)
            M[i, np.arange(a.size), a] += 1.0 / len(s)
    return M


def mean_trace_distances(
    samples: Sequence[Sequence[Sequence[int]]],
    n_actions: int,
    reached: Sequence[Sequence[bool]] | None = None,
    horizon: int | None = None,
) -> np.ndarray:
    """A distance between trace distributions: the padded sum (Eq 3.1) between the starts' mean
    traces (`mean_traces`), sum_t ||m_i(t) - m_j(t)||_1 over the first `horizon` steps (default: the
    median sample length - later steps are mostly the world's noise, once the traces have mixed)."""
    M = mean_traces(samples, n_actions, reached, horizon)
    flat = M.reshape(M.shape[0], -1)
    return np.abs(flat[:, None, :] - flat[None, :, :]).sum(axis=2)


ESTIMATORS = ("mode", "mean")


def estimate_distances(
    samples: Sequence[Sequence[Sequence[int]]], estimator: str, substitution_cost: int = 2
) -> np.ndarray:
    """Distances between start states from their sampled traces, by `estimator` ("mode" or "mean")."""
    if estimator == "mode":
        return mode_distances(samples, substitution_cost)
    if estimator == "mean":
        return mean_pair_distances(samples, substitution_cost)
    raise ValueError(f"estimator must be one of {ESTIMATORS}, not {estimator!r}")


def relative_change(D_new: np.ndarray, D_old: np.ndarray) -> float:
    """||D_new - D_old|| / ||D_new|| (Frobenius; 0 when both are zero): how much an estimate moved."""
    norm = float(np.linalg.norm(D_new))
    return float(np.linalg.norm(D_new - D_old)) / norm if norm > 0 else 0.0


@dataclass(frozen=True)
class SettledDistances:
    """What `sample_until_settled` ends with: the distance estimate, the samples per start, the
    relative change of the estimate at each added batch, and whether it settled below `tol`."""

    distances: np.ndarray
    samples: list[list[Trace]]
    changes: tuple[float, ...]
    settled: bool

    @property
    def n_samples(self) -> int:
        """Samples per start state when sampling stopped."""
        return len(self.samples[0]) if self.samples else 0


def sample_until_settled(
    sample: Callable[[int], Sequence[int]],
    n_starts: int,
    estimator: Callable[[list[list[Trace]]], np.ndarray],
    batch: int = 4,
    tol: float = 0.02,
    max_samples: int = 64,
    patience: int = 2,
) -> SettledDistances:
    """Sample traces from every start state in batches until the distance estimate settles.

    Parameters
    ----------
    sample : callable
        ``sample(start) -> trace``: runs the policy once from `start` (the world's randomness
        makes each call a new sample).
    n_starts : int
        Number of start states.
    estimator : callable
        Samples per start -> [n, n] distances (e.g. `mode_distances`, `mean_pair_distances`).
    batch : int, default 4
        Samples added per start at each round (the first round draws one batch).
    tol : float, default 0.02
        Stop when ||D_new - D_old|| / ||D_new|| < tol for `patience` consecutive rounds.
    max_samples : int, default 64
        Stop there regardless (``settled`` False if the estimate had not settled).
    patience : int, default 2
        Consecutive small changes required.

    Returns
    -------
    SettledDistances
    """
    if n_starts < 1 or batch < 1 or max_samples < batch or tol <= 0 or patience < 1:
        raise ValueError("need n_starts >= 1, batch >= 1, max_samples >= batch, tol > 0, patience >= 1")
    samples: list[list[Trace]] = [[] for _ in range(n_starts)]
    changes: list[float] = []
    D_old: np.ndarray | None = None
    calm = 0
    while True:
        for i in range(n_starts):
            samples[i].extend(tuple(int(a) for a in sample(i)) for _ in range(batch))
        D = estimator(samples)
        if D_old is not None:
            change = relative_change(D, D_old)
            changes.append(change)
            calm = calm + 1 if change < tol else 0
            if calm >= patience:
                return SettledDistances(D, samples, tuple(changes), True)
        if len(samples[0]) + batch > max_samples:
            return SettledDistances(D, samples, tuple(changes), False)
        D_old = D
