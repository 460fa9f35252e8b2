"""Which policy's map the generic program publishes: the pure rules, tested without a world.

A sweep runs a policy from every start state and is scored without truth (`sweep_score`: the
fraction of traces that reached the goal, and the mean length of those that did - every learner
learns shortest ways). A newer policy is compared with the accepted one (`compare`):

* deterministic world: more goals, or as many by shorter traces, is better; the same score is equal;
* stochastic world: goal fractions are estimates from sampled traces, so a newer policy is better
  only beyond the noise of both estimates (one-sided, 1.64 standard errors) or as good within it
  with traces a fifth shorter; as good within the noise is equal;
* net moves (the planner's `distance=net`): by `end_disparity`, how nearly the traces end where a
  similarity of their starts puts them, among policies that reach the goal from enough starts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sensorimotor.agent.embedding import procrustes_error

#: standard errors by which a sampled goal fraction must beat another's (one-sided, 95 %)
NOISE_Z = 1.64
#: as good within the noise counts as better when the traces are this much shorter
SHORTER = 0.8


@dataclass(frozen=True)
class Score:
    """A sweep's score: the goal fraction, the mean length of the traces that reached the goal
    (inf when none did), and how many traces the fraction was estimated from."""

    fraction: float
    length: float
    traces: int


@dataclass(frozen=True)
class Verdict:
    """How a newer policy compares with the accepted one."""

    better: bool
    equal: bool


def sweep_score(reached: list[bool], traces: list[list[int]]) -> Score:
    """The score of a sweep's traces and whether each reached the goal."""
    ok = [len(t) for t, r in zip(traces, reached, strict=True) if r]
    return Score(len(ok) / max(1, len(traces)), float(np.mean(ok)) if ok else float("inf"), len(traces))


def noise(new: Score, accepted: Score) -> float:
    """The one-sided noise margin of the difference of two sampled goal fractions (pooled)."""
    n, m = max(1, new.traces), max(1, accepted.traces)
    p = (new.fraction * n + accepted.fraction * m) / (n + m)
    return NOISE_Z * float(np.sqrt(max(p * (1 - p), 0.01) * (1 / n + 1 / m)))


def compare(new: Score, accepted: Score | None, stochastic: bool) -> Verdict:
    """A newer policy's sweep against the accepted one's (None: nothing accepted yet)."""
    if accepted is None:
        return Verdict(True, False)
    if stochastic:
        margin = noise(new, accepted)
        gain = new.fraction - accepted.fraction
        better = gain > margin or (abs(gain) <= margin and new.length < SHORTER * accepted.length)
        return Verdict(better, not better and gain >= -margin)
    better = new.fraction > accepted.fraction or (
        new.fraction == accepted.fraction and new.length < accepted.length - 1e-9
    )
    equal = new.fraction == accepted.fraction and new.length <= accepted.length + 1e-9
    return Verdict(better, equal)


def compare_ends(disparity: float, accepted: float, good: bool) -> Verdict:
    """Net-move maps: a newer policy that reaches the goal from enough starts (`good`) is better
    when its traces end more nearly where their starts would have them (`end_disparity`)."""
    return Verdict(good and disparity < accepted - 1e-12, good and abs(disparity - accepted) <= 1e-12)


def end_disparity(ends: dict[int, tuple[np.ndarray, np.ndarray]]) -> float | None:
    """How far a sweep's traces disagree about where they go: the Procrustes disparity (0 to 1) of
    each trace's displacement (its end less its start) against its start, in the coordinates the
    planner plans in; None without three starts apart, 1 when every trace goes the same way. The net
    move of a trace is its displacement over the body's gain, so a net-move map matches the starts
    (up to that gain) as far as the traces end where their starts would have them: at one goal, or
    where a similarity of the starts puts them. Policies that reach every goal can still disagree
    (the goal is a region): this ranks them with no truth."""
    if len(ends) < 3:
        return None
    s = np.array([v[0] for v in ends.values()], dtype=np.float64)
    e = np.array([v[1] for v in ends.values()], dtype=np.float64)
    if np.allclose(s, s[0]):
        return None
    if np.allclose(s - e, (s - e)[0]):
        return 1.0
    return procrustes_error(s, s - e)


__all__ = ["NOISE_Z", "SHORTER", "Score", "Verdict", "compare", "compare_ends", "end_disparity", "noise", "sweep_score"]
