"""Chapter 6 experiments on the object-pose world: sensorimotor embedding by the generic program
against PCA and Isomap on the same start images (Fig 6.2, 6.3), and the alignment task over the
learned coordinates (Fig 6.4). `chapter` is `sme reproduce objectpose`.

- embedding: the generic program (no world-specific code) learns toward the perceptual goal; each
  of its embeddings is scored by Procrustes against (pitch, yaw): error per LSPI iteration (the
  program iterates LSPI until the weights settle, at most 8 times, after each batch of samples,
  then embeds: the x axis counts every iteration).
- peers: PCA and Isomap (scikit-learn, 2 components) of the images seen from the start states,
  scored the same way; scree diagrams of all three.
- alignment: a target orientation is given as a point of the learned embedding; the state is the
  learned (pitch, yaw) of the current view (the start view it shows), features are Gaussian radial
  basis functions of those coordinates (centred on the learned points), reward 1 on reaching the target; LSPI iterates over one
  batch of random-action samples, and after each iteration the greedy policy is run from every
  start state: the fraction that reaches the target.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, procrustes_error
from sensorimotor.agent.learners.lspi import LSPI
from sensorimotor.agent.programs.generic import GenericProgram
from sensorimotor.tools.experiments import scoring
from sensorimotor.tools.experiments.scoring import score_points, scores_of
from sensorimotor.tools.experiments.shared import ci95, pool_map
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.objectpose import ObjectPoseWorld


@dataclass(frozen=True)
class EmbeddingRun:
    """The generic program on the object-pose world: one entry per published embedding."""

    lspi_iterations: list[int]
    errors: list[float]
    goal_reached: list[float]
    coordinates: np.ndarray  # the last embedding, one row per start state
    eigenvalues: list[float]  # of the last embedding (classical MDS)
    scores: dict[str, float] | None  # trustworthiness, continuity, dissimilarities of the last embedding
    world_steps: int
    seconds: float


def embed(world: ObjectPoseWorld, seed: int, embeddings: int, steps: int, **program: Any) -> EmbeddingRun:
    """Run the generic program on `world` until it has published `embeddings` embeddings (or
    `steps` world steps have passed)."""
    prog = GenericProgram(world.spec(), seed=seed, **program)
    t0 = time.perf_counter()
    run = run_inprocess(world, prog, steps, stop_when=lambda r: len(r.embeddings) >= embeddings)
    embs = run.embeddings
    if not embs:
        raise RuntimeError(f"no embedding after {run.steps} steps")
    return EmbeddingRun(
        [int(e.metrics["lspi_iterations"]) for e in embs],
        [float(e.procrustes_error if e.procrustes_error is not None else np.nan) for e in embs],
        [float(e.metrics["goal_reached_fraction"]) for e in embs],
        np.asarray(embs[-1].coordinates, dtype=np.float64),
        [float(v) for v in embs[-1].eigenvalues],
        scores_of(embs[-1]),
        run.steps,
        time.perf_counter() - t0,
    )


@dataclass(frozen=True)
class Peers:
    """PCA and Isomap of the start images, scored against the same truth."""

    pca_error: float
    isomap_error: float
    isomap_neighbours: int  # the neighbourhood size that scored best (reported: the peer's best case)
    pca_coordinates: np.ndarray
    isomap_coordinates: np.ndarray
    pca_scree: list[float]  # explained variance, normalised to sum 1 over the first 10
    isomap_scree: list[float]  # eigenvalues of the geodesic distances' MDS, same normalisation
    isomap_errors: dict[int, float]  # Procrustes error for each neighbourhood size tried


def _scree(values: np.ndarray, k: int = 10) -> list[float]:
    v = np.clip(np.asarray(values, dtype=np.float64)[:k], 0.0, None)
    return (v / v.sum()).tolist() if v.sum() > 0 else v.tolist()


def peers(images: np.ndarray, truth: np.ndarray, neighbours: tuple[int, ...] = (4, 6, 8, 12)) -> Peers:
    """PCA and Isomap (2 components) of `images` (one flattened row per start state); Isomap with
    each neighbourhood size of `neighbours`, the best kept."""
    from sklearn.decomposition import PCA
    from sklearn.manifold import Isomap

    X = np.asarray(images, dtype=np.float64).reshape(len(images), -1)
    pca = PCA(n_components=min(10, *X.shape)).fit(X)
    pca_xy = pca.transform(X)[:, :2]
    best: tuple[float, int, np.ndarray, np.ndarray] | None = None
    errors: dict[int, float] = {}
    for k in neighbours:
        if k >= X.shape[0]:
            continue
        iso = Isomap(n_neighbors=k, n_components=2)
        xy = iso.fit_transform(X)
        err = procrustes_error(truth, xy)
        errors[k] = err
        if best is None or err < best[0]:
            # the scree of the geodesic distances, by the same classical MDS as the sensorimotor embedding
            best = (err, k, xy, classical_mds(iso.dist_matrix_, 2).eigenvalues)
    if best is None:
        raise ValueError(f"{X.shape[0]} images: too few for Isomap with {neighbours} neighbours")
    return Peers(
        procrustes_error(truth, pca_xy),
        best[0],
        best[1],
        pca_xy,
        best[2],
        _scree(pca.explained_variance_),
        _scree(best[3]),
        errors,
    )


# --- the alignment task (Fig 6.4) ----------------------------------------------------------------


class CoordinateRBF:
    """LSPI basis over start-state ids: the learned coordinates of the state, through Gaussian
    radial basis functions centred on the learned points themselves (width: the median distance
    to the nearest other point; invariant to the embedding's arbitrary rotation), plus a constant,
    one block per action."""

    def __init__(self, coordinates: np.ndarray, n_actions: int, width: float = 1.0) -> None:
        self.coordinates = np.asarray(coordinates, dtype=np.float64)
        self.n_actions = n_actions
        c = self.coordinates
        d = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=2)
        d[np.diag_indices_from(d)] = np.inf
        self.width = width * (float(np.median(d.min(axis=1))) or 1.0)
        self._f = np.hstack([np.ones((len(c), 1)), np.exp(-0.5 * (d**2) / self.width**2) + np.eye(len(c))])

    @property
    def k(self) -> int:
        return self._f.shape[1] * self.n_actions

    def phi(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        f = self._f[np.asarray(states, dtype=np.int64).reshape(-1)]
        a = np.asarray(actions, dtype=np.int64).reshape(-1)
        m = f.shape[1]
        out = np.zeros((f.shape[0], self.k))
        for j in range(self.n_actions):
            out[a == j, j * m : (j + 1) * m] = f[a == j]
        return out


@dataclass
class Alignment:
    """Fraction of start states whose greedy policy reaches the target, after each LSPI iteration."""

    target: int
    success: list[float] = field(default_factory=list)
    mean_steps: list[float] = field(default_factory=list)


def _view_id(world: ObjectPoseWorld, views: np.ndarray, img: np.ndarray) -> int:
    """Which start view the image shows (the nearest; the scene is static, so it is exact)."""
    return int(np.argmin(((views - np.asarray(img, dtype=np.float64).reshape(1, -1)) ** 2).sum(axis=1)))


def alignment(
    world: ObjectPoseWorld,
    coordinates: np.ndarray,
    seed: int,
    iterations: int = 5,
    samples: int = 1500,
    max_steps: int | None = None,
) -> Alignment:
    """Learn to turn the object to a target given in the learned coordinates (see module docstring)."""
    rng = np.random.default_rng([seed, 64])
    n = len(world.poses)
    views = np.array([world.observe(q).reshape(-1) for q in world.poses], dtype=np.float64)
    target = int(rng.integers(n))
    n_actions = world.spec().action_space.n
    lspi = LSPI(CoordinateRBF(np.asarray(coordinates, dtype=np.float64), n_actions), gamma=0.9, capacity=samples)
    limit = max_steps or 4 * world.params.half_range + 4

    def turn(s: int, a: int) -> int:  # the world's answer to action a in the view of start state s
        world.reset(start=s)
        return _view_id(world, views, world.step(np.array([float(a)])).tensors["camera"])

    s = int(rng.integers(n))
    t = 0
    for _ in range(samples):  # random actions from random starts; an episode ends at the target
        a = int(rng.integers(n_actions))
        s2 = turn(s, a)
        done = s2 == target
        lspi.learn_one(s, a, 1.0 if done else 0.0, s2, done)
        t += 1
        s, t = (int(rng.integers(n)), 0) if done or t >= limit else (s2, t)
    out = Alignment(target)
    for _ in range(iterations):
        lspi.iterate()
        reached, lengths = 0, []
        for start in range(n):
            s, k = start, 0
            while s != target and k < limit:
                s = turn(s, lspi.greedy(s))
                k += 1
            reached += s == target
            lengths.append(k)
        out.success.append(reached / n)
        out.mean_steps.append(float(np.mean(lengths)))
    return out


# --- one seed, and the chapter -------------------------------------------------------------------


def job(seed: int, half_range: int, embeddings: int, steps: int, align_iterations: int, samples: int) -> dict[str, Any]:
    """Everything of one seed: the embedding run (the generic program with its defaults but
    `samples` new random-action samples between policy iterations), the peers and the alignment
    task. One BLAS thread: the matrices are small and worker processes already share the cores."""
    from threadpoolctl import threadpool_limits

    world = ObjectPoseWorld(seed=seed, half_range=half_range)
    try:
        with threadpool_limits(1):
            truth = world.truth().tensors["positions"]
            goal = world.goal
            run = embed(world, seed, embeddings, steps, samples_per_iteration=samples)
            images = np.array([world.observe(q) for q in world.poses])
            pe = peers(images, truth)
            al = alignment(world, run.coordinates, seed, iterations=align_iterations)
    finally:
        world.close()
    return {
        "seed": seed,
        "goal": list(goal),
        "lspi_iterations": run.lspi_iterations,
        "errors": run.errors,
        "goal_reached": run.goal_reached,
        "final_error": run.errors[-1],
        "eigenvalues": run.eigenvalues,
        "coordinates": run.coordinates.tolist(),
        "world_steps": run.world_steps,
        "seconds": run.seconds,
        "scores": run.scores,
        "pca_scores": score_points(truth, pe.pca_coordinates),
        "isomap_scores": score_points(truth, pe.isomap_coordinates),
        "pca_error": pe.pca_error,
        "isomap_error": pe.isomap_error,
        "isomap_neighbours": pe.isomap_neighbours,
        "isomap_errors": {str(k): v for k, v in pe.isomap_errors.items()},
        "pca_scree": pe.pca_scree,
        "isomap_scree": pe.isomap_scree,
        "pca_coordinates": pe.pca_coordinates.tolist(),
        "isomap_coordinates": pe.isomap_coordinates.tolist(),
        "truth": truth.tolist(),
        "alignment_target": al.target,
        "alignment_success": al.success,
        "alignment_steps": al.mean_steps,
    }


def _plot_fig63(out: str, res: list[dict[str, Any]]) -> None:
    """Fig 6.3: (a) Procrustes error per LSPI iteration, PCA and Isomap as lines; (b) scree."""
    from sensorimotor.tools.common import require

    matplotlib = require("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for r in res:
        a.plot(r["lspi_iterations"], r["errors"], color="C0", lw=0.8, alpha=0.6, marker=".")
    a.plot([], [], color="C0", label="sensorimotor embedding (per seed)")
    a.axhline(float(np.mean([r["pca_error"] for r in res])), color="C1", ls="--", label="PCA")
    a.axhline(float(np.mean([r["isomap_error"] for r in res])), color="C2", ls=":", label="Isomap")
    a.set(
        yscale="log",
        xlabel="LSPI iterations",
        ylabel="Procrustes error",
        title="(a) Procrustes error per LSPI iteration",
    )
    a.legend(fontsize=8)
    k = np.arange(1, 11)
    for key, label, colour in (
        ("se_scree", "sensorimotor embedding", "C0"),
        ("pca_scree", "PCA", "C1"),
        ("isomap_scree", "Isomap", "C2"),
    ):
        v = np.mean(
            [np.resize(r[key], 10) if len(r[key]) >= 10 else np.pad(r[key], (0, 10 - len(r[key]))) for r in res], axis=0
        )
        b.plot(k, v, marker="o", color=colour, label=label)
    b.set(xlabel="component", ylabel="eigenvalue / sum of the first 10", title="(b) scree")
    b.legend(fontsize=8)
    fig.suptitle("Object pose: Procrustes error and eigenvalues (Fig 6.3)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "objectpose_fig6_3.png"), dpi=110)
    plt.close(fig)

    fig, axs = plt.subplots(1, 4, figsize=(14, 3.6))
    r = res[0]
    for ax, key, title in zip(
        axs,
        ("truth", "pca_coordinates", "isomap_coordinates", "coordinates"),
        (
            "(a) truth (pitch, yaw)",
            "(b) PCA",
            f"(c) Isomap ({r['isomap_neighbours']} neighbours)",
            "(d) sensorimotor embedding",
        ),
        strict=True,
    ):
        xy = np.asarray(r[key])
        ax.scatter(xy[:, 1], xy[:, 0], c=np.asarray(r["truth"])[:, 1], cmap="viridis", s=18)
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
    fig.suptitle(f"Object pose results, seed {r['seed']} (Fig 6.2; colour: true yaw)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "objectpose_fig6_2.png"), dpi=110)
    plt.close(fig)


def _plot_fig64(out: str, res: list[dict[str, Any]]) -> None:
    """Fig 6.4: the fraction of starts that reach the target, per LSPI iteration of the alignment task."""
    from sensorimotor.tools.common import require

    matplotlib = require("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for r in res:
        it = np.arange(1, len(r["alignment_success"]) + 1)
        a.plot(it, r["alignment_success"], marker="o", lw=0.8, label=f"seed {r['seed']}")
        b.plot(it, r["alignment_steps"], marker="o", lw=0.8)
    a.axhline(0.95, color="k", ls="--", lw=0.8)
    a.set(xlabel="LSPI iteration", ylabel="starts that reach the target", title="(a) success", ylim=(0, 1.05))
    b.set(xlabel="LSPI iteration", ylabel="mean steps (limit when missed)", title="(b) steps to the target")
    if len(res) <= 10:
        a.legend(fontsize=7)
    fig.suptitle("Pose alignment over the learned coordinates (Fig 6.4)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "objectpose_fig6_4.png"), dpi=110)
    plt.close(fig)


def chapter(runs: int, quick: bool, workers: int, out: str) -> dict[str, Any]:
    """`sme reproduce objectpose`: the table (sensorimotor embedding vs PCA vs Isomap, 95 % CIs
    over seeds), Fig 6.2, 6.3 and 6.4."""

    half_range, embeddings, steps, samples = (2, 8, 8_000, 100) if quick else (3, 10, 30_000, 200)
    res = pool_map(job, [(s, half_range, embeddings, steps, 5, samples) for s in range(runs)], workers)
    for r in res:
        r["se_scree"] = _normalised(r["eigenvalues"])
    se = ci95([r["final_error"] for r in res])
    pca = ci95([r["pca_error"] for r in res])
    iso = ci95([r["isomap_error"] for r in res])
    first = ci95([r["errors"][0] for r in res])
    within = [next((i + 1 for i, s in enumerate(r["alignment_success"]) if s >= 0.95), None) for r in res]
    last_align = ci95([r["alignment_success"][-1] for r in res])
    n = (2 * half_range + 1) ** 2
    best_peer = min(pca[0], iso[0])

    def f(ci: tuple[float, float], d: int = 4) -> str:
        return f"{ci[0]:.{d}f} ± {ci[1]:.{d}f}"

    lines = [
        f"Object pose (ch. 6): {runs} seeded runs; {n} start poses (pitch x yaw, ±{half_range} steps of π/16); "
        "Procrustes error against (pitch, yaw), mean ± 95 % CI over seeds.",
        "",
        f"| method | Procrustes error | {scoring.HEADER} | dissertation |",
        "|---|---|---|---|",
        f"| sensorimotor embedding (generic program), first embedding | {f(first)} | | higher at first |",
        f"| sensorimotor embedding, after {embeddings} embeddings | {f(se)} | {scoring.cell([r['scores'] for r in res])} "
        "| far lower than PCA and Isomap |",
        f"| PCA of the start images | {f(pca)} | {scoring.cell([r['pca_scores'] for r in res])} | poor |",
        f"| Isomap of the start images (best of 4, 6, 8, 12 neighbours) | {f(iso)} "
        f"| {scoring.cell([r['isomap_scores'] for r in res])} | poor |",
        "",
        f"Sensorimotor embedding / better peer: {se[0] / best_peer:.3f} (goal ≤ 1/3). "
        f"Goal pose found per seed (pitch, yaw steps): {[tuple(r['goal']) for r in res]}.",
        "",
        f"Alignment (Fig 6.4): starts that reach the target after 5 LSPI iterations {f(last_align, 3)}; "
        f"first LSPI iteration with ≥ 95 % per seed: {within}.",
    ]
    _plot_fig63(out, res)
    _plot_fig64(out, res)
    return {
        "results": res,
        "summary": {
            "se_error": se,
            "se_first_error": first,
            "pca_error": pca,
            "isomap_error": iso,
            "ratio_to_better_peer": se[0] / best_peer,
            "alignment_final_success": last_align,
            "alignment_first_iteration_95": within,
            "half_range": half_range,
        },
        "markdown": "\n".join(lines),
    }


def _normalised(eigenvalues: list[float], k: int = 10) -> list[float]:
    return _scree(np.asarray(eigenvalues), k)
