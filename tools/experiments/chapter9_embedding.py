"""Chapter 9's embedding experiments: probabilistic sensorimotor embedding in a slippery gridworld
(9.4: plain, mode and mean-distance estimators, adaptive sampling) and two variations (9.5: Isomap
in place of MDS; state-aided vergence traces). Each `*_job` is one seeded run for `sme reproduce`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, procrustes_error, trace_distances
from sensorimotor.agent.embedding.probabilistic import mean_pair_distances, mode_distances, sample_until_settled
from sensorimotor.agent.learners.lspi import LSPI, TabularBasis
from sensorimotor.tools.experiments.scoring import score_points
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
    field_scores: dict[str, dict[str, float] | None] = field(default_factory=dict)  # estimator -> scoring.score_points


def probabilistic_gridworld(
    seed: int, slip: float = 0.2, size: int = 9, tol: float = 0.02, max_samples: int = 64
) -> ProbabilisticResult:
    """Plain (one sampled trace per start) against the two ch. 9.4 estimators, in a gridworld whose
    moves slip sideways with probability `slip`; LSPI policy learnt in the same slippery world."""
    world = GridWorld(seed=seed, size=size, slip=slip)
    lspi = train_lspi_gridworld(world, seed)
    truth = world.truth().tensors["positions"]
    n = len(world.cells)

    fields: dict[str, dict[str, float] | None] = {}

    def err(D: np.ndarray, name: str) -> float:
        X = classical_mds(D, 2).coordinates
        fields[name] = score_points(truth, X)
        return procrustes_error(truth, X)

    plain = [greedy_trace(world, lspi, i) for i in range(n)]
    e_plain = err(trace_distances(plain, kind="edit", substitution_cost=2), "plain")
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
        err(mode.distances, "mode"),
        err(mean.distances, "mean"),
        err(mean_pair_distances(mean.samples, debias=True), "mean_debiased"),
        mode.n_samples,
        mean.n_samples,
        fields,
    )


def probabilistic_job(seed: int, slip: float, size: int = 9) -> dict[str, Any]:
    """`probabilistic_gridworld` as a picklable job returning a dict."""
    return dict(probabilistic_gridworld(seed, slip, size).__dict__)


# --- variations (9.5) -----------------------------------------------------------------------------


def isomap_coordinates(D: np.ndarray, dims: int = 2, n_neighbors: int = 8) -> np.ndarray:
    """Isomap (scikit-learn) over precomputed trace distances: a non-linear embedding in place of MDS."""
    from sklearn.manifold import Isomap

    return Isomap(n_neighbors=n_neighbors, n_components=dims, metric="precomputed").fit_transform(D)


def isomap_job(seed: int, barrier: bool) -> dict:
    """Plain (classical MDS) against Isomap on the same LSPI traces of the (barrier) gridworld."""
    world = GridWorld(seed=seed, barrier=barrier)
    lspi = train_lspi_gridworld(world, seed)
    traces = [greedy_trace(world, lspi, i) for i in range(len(world.cells))]
    D = trace_distances(traces, kind="edit", substitution_cost=2)
    truth = world.truth().tensors["positions"]
    mds, iso = classical_mds(D, 2).coordinates, isomap_coordinates(D)
    return {
        "seed": seed,
        "barrier": barrier,
        "mds": procrustes_error(truth, mds),
        "isomap": procrustes_error(truth, iso),
        "mds_scores": score_points(truth, mds),
        "isomap_scores": score_points(truth, iso),
    }


def far_error(truth: np.ndarray, embedding: np.ndarray, far: np.ndarray) -> float:
    """Mean |aligned - truth| over the `far` rows after a least-squares affine fit of the 1-D
    embedding onto the 1-D truth over all rows (in the truth's units)."""
    t, e = np.asarray(truth, dtype=np.float64).reshape(-1), np.asarray(embedding, dtype=np.float64).reshape(-1)
    A = np.c_[e, np.ones_like(e)]
    coef, *_ = np.linalg.lstsq(A, t, rcond=None)
    return float(np.abs(A @ coef - t)[far].mean())


def substep_offset(d: np.ndarray, g: int) -> float:
    """Where between vergence steps the minimum of d lies, from the states seen around the end of
    the trace: the vertex of the parabola through d(g-1), d(g), d(g+1), in steps (|offset| <= 0.5)."""
    if g < 1 or g + 1 >= d.size:
        return 0.0
    a, b, c = float(d[g - 1]), float(d[g]), float(d[g + 1])
    den = a - 2 * b + c
    return float(np.clip(0.5 * (a - c) / den, -0.5, 0.5)) if den > 0 else 0.0


def state_aided_job(n_starts: int = 20) -> dict:
    """Vergence traces of ch. 7 (the perfect policy: converge to the perceptual goal) against the
    same traces aided by state (9.5). Plain: indel edit distance of the actions, i.e. differences of
    trace lengths, which alias at far depths where several starts share a goal step. State-aided:
    the trace length refined by the foveal differences d (Eq 7.2) seen at the trace's end - one step
    before, at, and one probe step past the goal - as the parabola's vertex (`substep_offset`)."""
    from sensorimotor.worlds.vergence import VergenceWorld

    w = VergenceWorld(seed=0, n_starts=n_starts)
    try:
        goals, offsets = [], []
        for st in range(w.spec().n_starts):
            w.reset(start=st)
            d = w.differences(range(max(w.goal - 1, 0), w.goal + 2))
            goals.append(w.goal)
            offsets.append(substep_offset(np.r_[np.zeros(max(w.goal - 1, 0)), d], w.goal))
        truth = w.truth().tensors["positions"][:, 0]
    finally:
        w.close()
    D_plain = trace_distances([[0] * g for g in goals], kind="edit", substitution_cost=2)
    refined = np.asarray(goals, dtype=np.float64) + np.asarray(offsets)
    D_aided = np.abs(refined[:, None] - refined[None, :])
    far = np.argsort(-np.asarray(truth))[len(truth) // 2 :]  # the smaller angles: the farther half
    out: dict[str, Any] = {
        "n_starts": n_starts,
        "aliased_far_starts": int(len(far) - len({goals[i] for i in far})),
    }
    for name, D in (("plain", D_plain), ("state_aided", D_aided)):
        X = classical_mds(D, 1).coordinates
        out[name] = {
            "procrustes": procrustes_error(truth, X),
            "far_error_rad": far_error(truth, X, far),
            "scores": score_points(truth, X),
        }
    return out
