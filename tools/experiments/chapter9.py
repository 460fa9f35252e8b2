"""Chapter 9 experiments (beyond the dissertation): probabilistic sensorimotor embedding in a
slippery gridworld, option discovery, policy maps of the mountain car, and two variations
(Isomap in place of MDS; state-aided vergence traces)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, procrustes_error, trace_distances
from sensorimotor.agent.embedding.probabilistic import (
    mean_pair_distances,
    mode_distances,
    sample_until_settled,
)
from sensorimotor.agent.learners.lspi import LSPI, TabularBasis
from sensorimotor.worlds.gridworld import GridWorld

# --- probabilistic sensorimotor embedding (9.4) --------------------------------------------------


def train_lspi_gridworld(world: GridWorld, seed: int, samples: int = 8000, iterations: int = 12) -> LSPI:
    """LSPI on uniformly random-walk samples of `world` (as the ch. 5 program explores)."""
    rng = np.random.default_rng(seed)
    n_actions = len(world.moves)
    lspi = LSPI(TabularBasis(len(world.cells), n_actions), gamma=0.9, ridge=1e-3, capacity=samples)
    s = int(world.reset(start=-1).tensors["state"][0])
    for _ in range(samples):
        a = int(rng.integers(n_actions))
        r = world.step(np.array([a]))
        s2 = int(r.tensors["state"][0])
        lspi.learn_one(s, a, r.reward, s2, r.done)
        s = int(world.reset(start=-1).tensors["state"][0]) if r.done else s2
    for _ in range(iterations):
        if lspi.iterate() < 1e-6:
            break
    return lspi


def greedy_trace(world: GridWorld, lspi: LSPI, start: int, max_trace: int = 60) -> list[int]:
    """One trace of the greedy policy from `start` (a new sample each call when the world slips)."""
    r = world.reset(start=start)
    trace: list[int] = []
    while not r.done and len(trace) < max_trace:
        a = lspi.greedy(int(r.tensors["state"][0]), trace[-1] if trace else None)
        trace.append(a)
        r = world.step(np.array([a]))
    return trace


@dataclass(frozen=True)
class ProbabilisticResult:
    """Procrustes errors of the plain, mode and mean-distance estimators on one world, and the
    samples per start the adaptive sampling chose for each."""

    seed: int
    slip: float
    plain: float
    mode: float
    mean: float
    mean_debiased: float
    samples_mode: int
    samples_mean: int


def probabilistic_gridworld(
    seed: int, slip: float = 0.2, size: int = 9, tol: float = 0.02, max_samples: int = 64
) -> ProbabilisticResult:
    """Plain (one sampled trace per start) against the two ch. 9.4 estimators, in a gridworld whose
    moves slip sideways with probability `slip`; LSPI policy learnt in the same slippery world."""
    world = GridWorld(seed=seed, size=size, slip=slip)
    lspi = train_lspi_gridworld(world, seed)
    truth = world.truth().tensors["positions"]
    n = len(world.cells)

    def err(D: np.ndarray) -> float:
        return procrustes_error(truth, classical_mds(D, 2).coordinates)

    plain = [greedy_trace(world, lspi, i) for i in range(n)]
    e_plain = err(trace_distances(plain, kind="edit", substitution_cost=2))
    mode = sample_until_settled(
        lambda i: greedy_trace(world, lspi, i), n, mode_distances, tol=tol, max_samples=max_samples
    )
    mean = sample_until_settled(
        lambda i: greedy_trace(world, lspi, i), n, mean_pair_distances, tol=tol, max_samples=max_samples
    )
    return ProbabilisticResult(
        seed,
        slip,
        e_plain,
        err(mode.distances),
        err(mean.distances),
        err(mean_pair_distances(mean.samples, debias=True)),
        mode.n_samples,
        mean.n_samples,
    )


def probabilistic_job(seed: int, slip: float) -> dict[str, Any]:
    """`probabilistic_gridworld` as a picklable job returning a dict."""
    return probabilistic_gridworld(seed, slip).__dict__
