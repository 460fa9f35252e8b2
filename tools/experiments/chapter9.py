"""Chapter 9 experiments (beyond the dissertation): probabilistic sensorimotor embedding in a
slippery gridworld, option discovery, policy maps of the mountain car, and two variations
(Isomap in place of MDS; state-aided vergence traces)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, procrustes_error, trace_distances
from sensorimotor.agent.embedding.probabilistic import (
    mean_pair_distances,
    mode_distances,
    sample_until_settled,
)
from sensorimotor.agent.learners.lspi import LSPI, TabularBasis
from sensorimotor.tools.experiments import scoring
from sensorimotor.tools.experiments.scoring import score_points
from sensorimotor.tools.experiments.shared import ci95, fmt, pool_map
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


# --- option discovery (9.6, Fig 9.3) ----------------------------------------------------------


@dataclass(frozen=True)
class GridTable:
    """A deterministic gridworld as tables: next cell of (cell, move), the goal cell, BFS distances."""

    next: np.ndarray  # [n_cells, n_moves]
    goal: int
    dist: np.ndarray  # [n_cells] shortest path length to the goal

    @staticmethod
    def of(world: GridWorld) -> GridTable:
        n, m = len(world.cells), len(world.moves)
        nxt = np.empty((n, m), dtype=np.int64)
        for i, (x, y) in enumerate(world.cells):
            for a, (dx, dy) in enumerate(world.moves):
                c = (x + dx, y + dy)
                nxt[i, a] = world.index.get(c, i)
        goal = world.index[world.goal]
        dist = np.full(n, -1, dtype=np.int64)
        dist[goal], frontier = 0, [goal]
        while frontier:  # BFS backwards (moves are reversible in a gridworld)
            new = []
            for cell in frontier:
                for nb in nxt[cell]:
                    if dist[nb] < 0:
                        dist[nb] = dist[cell] + 1
                        new.append(int(nb))
            frontier = new
        return GridTable(nxt, goal, dist)


def greedy_steps(table: GridTable, agent: Any, starts: np.ndarray, cap: int = 200) -> float:
    """Mean primitive steps to the goal of the agent's greedy choices from each start (cap if never)."""
    total = 0
    for s0 in starts:
        s, t = int(s0), 0
        while s != table.goal and t < cap:
            for a in agent.actions_of(agent.greedy(s)):
                s, t = int(table.next[s, a]), t + 1
                if s == table.goal or t >= cap:
                    break
        total += t
    return total / len(starts)


@dataclass(frozen=True)
class OptionCurve:
    """Greedy steps to goal after every `every` training steps, and the first training step at
    which it reached `level` (None: never within the budget)."""

    steps: list[int]
    mean_steps: list[float]
    steps_to_level: int | None


def train_options_agent(
    table: GridTable,
    options: list[tuple[int, ...]],
    seed: int,
    budget: int,
    level: float,
    every: int = 500,
    n_eval: int = 40,
    max_episode: int = 300,
) -> tuple[OptionCurve, Any]:
    """SMDP Q-learning with `options` (none: primitives only) from random starts, each step of an
    option also updating its primitive action (intra-option); training steps count primitive world steps. Stops at the budget or once greedy steps to goal <= `level`."""
    from sensorimotor.agent.learners.smdp_q import OptionQLearner

    n = table.next.shape[0]
    agent = OptionQLearner(n, table.next.shape[1], options, alpha=0.5, gamma=0.95, epsilon=0.1, seed=seed)
    rng = np.random.default_rng(seed)
    free = np.flatnonzero(np.arange(n) != table.goal)
    evals = np.random.default_rng(9_000).choice(free, size=min(n_eval, free.size), replace=False)
    steps: list[int] = []
    means: list[float] = []
    t, hit = 0, None
    while t < budget and hit is None:
        s, ep = int(rng.choice(free)), 0
        while s != table.goal and ep < max_episode and hit is None:
            c = agent.choose(s)
            s0, R, k = s, 0.0, 0
            for a in agent.actions_of(c):
                prev, s = s, int(table.next[s, a])
                k += 1
                t += 1
                ep += 1
                if c >= agent.n_actions:  # intra-option learning: each step also teaches its primitive
                    agent.update(prev, a, float(s == table.goal), 1, s, s == table.goal)
                if s == table.goal:
                    R += agent.gamma ** (k - 1)
                    break
                if t % every == 0:
                    steps.append(t)
                    means.append(greedy_steps(table, agent, evals))
                    if means[-1] <= level:
                        hit = t
            agent.update(s0, c, R, k, s, s == table.goal)
    return OptionCurve(steps, means, hit), agent


def option_world(size: int = 15) -> GridWorld:
    """The options world: a `size` x `size` gridworld with the goal in a far corner."""
    return GridWorld(seed=0, size=size, goal=(size - 1, size - 1), max_episode_steps=10**6)


def options_job(seed: int, budget: int, n_options: int = 4, size: int = 15, level_factor: float = 1.25) -> dict:
    """One seed of Fig 9.3: a primitives-only agent trained (source seed) gives traces from every
    start; options discovered from them; new agents with none / random / discovered options, same seed."""
    from sensorimotor.agent.embedding.options import discover_options, random_options

    table = GridTable.of(option_world(size))
    free = np.flatnonzero(np.arange(table.next.shape[0]) != table.goal)
    level = level_factor * float(table.dist[np.random.default_rng(9_000).choice(free, size=40, replace=False)].mean())
    # the trained policy: a primitives-only agent trained to the level, its greedy traces from every start
    _, source = train_options_agent(table, [], 10_000 + seed, 10 * budget, level)
    traces = []
    for s0 in free:
        s, tr = int(s0), list[int]()
        while s != table.goal and len(tr) < 200:
            a = source.greedy(s)
            tr.append(a)
            s = int(table.next[s, a])
        traces.append(tr)
    found = discover_options(traces, n_options=n_options, seed=seed)
    rand = random_options(table.next.shape[1], len(found.options), seed=seed)
    out: dict[str, Any] = {"seed": seed, "level": level, "discovered_options": found.options, "random_options": rand}
    for name, opts in (("none", []), ("random", rand), ("discovered", found.options)):
        curve, _ = train_options_agent(table, opts, seed, budget, level)
        out[name] = {"steps": curve.steps, "mean_steps": curve.mean_steps, "steps_to_level": curve.steps_to_level}
    return out


# --- policy maps (9.6, Fig 9.2) -----------------------------------------------------------------

OUTCOMES = ("failure", "direct", "rocking")


def train_mountaincar(seed: int, train_steps: int, tiles: int = 10, n_tilings: int = 8) -> Any:
    """Sarsa(lambda) with tile coding on the true (x, v) for `train_steps` car steps (as ch. 8's
    true-state agent): the trained policy whose behaviour a policy map shows."""
    from sensorimotor.tools.experiments.mountaincar import true_state_agent, true_state_episode
    from sensorimotor.worlds.mountaincar_dynamics import MountainCarParams

    prm = MountainCarParams()
    rng = np.random.default_rng(seed)
    agent = true_state_agent(seed, prm, tiles, n_tilings)
    n = 0
    while n < train_steps:
        n += true_state_episode(agent, rng, prm, 1000)
    return agent


def mountaincar_traces(agent: Any, n: int, seed: int, cap: int = 300) -> tuple[list[list[int]], list[str]]:
    """Greedy traces of `agent` from `n` random (x, v) starts and each start's true outcome:
    ``failure`` (no goal within `cap` car steps), ``direct`` (goal without the car ever moving
    backwards after its start) or ``rocking`` (goal after at least one backward swing)."""
    from sensorimotor.worlds.mountaincar_dynamics import MountainCarParams, random_state
    from sensorimotor.worlds.mountaincar_dynamics import step as car_step

    prm = MountainCarParams()
    rng = np.random.default_rng(seed)
    traces, outcomes = [], []
    for _ in range(n):
        x, v = random_state(rng, prm)
        tr: list[int] = []
        backward, done = False, False
        while not done and len(tr) < cap:
            a = agent.greedy(np.array([x, v]))
            tr.append(a)
            x, v, done = car_step(x, v, a - 1, prm)
            backward |= v < 0 and len(tr) > 1
        traces.append(tr)
        outcomes.append("failure" if not done else ("rocking" if backward else "direct"))
    return traces, outcomes


def policy_map_job(seed: int, train_steps: int, n_starts: int, n_clusters: int | None = 3) -> dict:
    """Fig 9.2 on one seed: train, trace from `n_starts` random starts, map, and score the clusters
    against the true outcomes (each cluster's majority outcome and its purity)."""
    from sensorimotor.agent.embedding.policy_map import policy_map

    agent = train_mountaincar(seed, train_steps)
    traces, outcomes = mountaincar_traces(agent, n_starts, seed + 1)
    pm = policy_map(traces, n_clusters=n_clusters, seed=seed)
    clusters = []
    out = np.array(outcomes)
    for c in range(pm.n_clusters):
        members = out[pm.labels == c]
        counts = {o: int((members == o).sum()) for o in OUTCOMES}
        major = max(counts, key=lambda o: counts[o])
        clusters.append(
            {
                "cluster": c,
                "size": int(members.size),
                "majority": major,
                "purity": counts[major] / max(1, members.size),
                "outcomes": counts,
            }
        )
    return {
        "seed": seed,
        "coordinates": pm.coordinates.tolist(),
        "labels": pm.labels.tolist(),
        "outcomes": outcomes,
        "clusters": clusters,
        "silhouette": pm.silhouette,
        "mean_length": float(np.mean([len(t) for t in traces])),
    }


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


# --- sme reproduce chapter9 -------------------------------------------------------------------------

AGENTS = ("none", "random", "discovered")


def _figure(out: str, name: str, draw: Any, ncols: int = 1, width: float = 6.4) -> None:
    """A matplotlib figure of `ncols` panels drawn by `draw(axes)`, saved as OUT/name."""
    import os

    from sensorimotor.tools.common import require

    matplotlib = require("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, ncols, figsize=(width, 4.0), squeeze=False)
    draw(list(axes[0]))
    fig.tight_layout()
    fig.savefig(os.path.join(out, name), dpi=110)
    plt.close(fig)


def _censored(r: dict, name: str, budget: int) -> float:
    v = r[name]["steps_to_level"]
    return float(budget if v is None else v)


def chapter(runs: int, quick: bool, workers: int, out: str) -> dict:
    """`sme reproduce chapter9`: probabilistic embedding, options, policy maps, variations."""
    from scipy import stats

    budget, opt_size = (40_000, 15) if quick else (80_000, 15)
    pm_train, pm_starts = (30_000, 500) if quick else (30_000, 1000)
    slip_size = 7 if quick else 9
    runs = min(runs, 5) if quick else runs
    seeds = list(range(runs))

    prob = pool_map(probabilistic_job, [(s, 0.2, slip_size) for s in seeds], workers)
    opts = pool_map(options_job, [(s, budget, 4, opt_size) for s in seeds], workers)
    maps = pool_map(policy_map_job, [(s, pm_train, pm_starts, 5) for s in seeds], workers)
    iso = pool_map(isomap_job, [(s, b) for b in (False, True) for s in seeds], workers)
    verg = pool_map(state_aided_job, [(n,) for n in ((20,) if quick else (20, 30, 40))], workers)

    # options: training steps to the level (censored at the budget when never reached)
    level = opts[0]["level"]
    to_level = {a: [_censored(r, a, budget) for r in opts] for a in AGENTS}
    steps_to_level = {
        a: {
            "mean": ci95(v)[0],
            "ci95": ci95(v)[1],
            "runs": v,
            "reached": sum(r[a]["steps_to_level"] is not None for r in opts),
        }
        for a, v in to_level.items()
    }
    welch = {
        f"discovered vs {b}": float(stats.ttest_ind(to_level["discovered"], to_level[b], equal_var=False).pvalue)
        if runs > 1
        else float("nan")
        for b in ("none", "random")
    }
    saving = 1.0 - float(np.mean(to_level["discovered"])) / float(np.mean(to_level["none"]))
    # policy maps: clusters per seed, and which true outcomes have a cluster of their own
    covered = [sorted({c["majority"] for c in m["clusters"] if c["purity"] >= 0.6 and c["size"] >= 5}) for m in maps]
    prob_ci = {k: ci95([r[k] for r in prob]) for k in ("plain", "mode", "mean", "mean_debiased")}
    samples = {k: ci95([r[k] for r in prob]) for k in ("samples_mode", "samples_mean")}
    iso_ci = {(b, k): ci95([r[k] for r in iso if r["barrier"] == b]) for b in (False, True) for k in ("mds", "isomap")}

    def pcell(name: str) -> str:
        return scoring.cell([r["field_scores"].get(name) for r in prob])

    def icell(barrier: bool, key: str) -> str:
        return scoring.cell([r[f"{key}_scores"] for r in iso if r["barrier"] == barrier])

    L = [
        f"Chapter 9 (beyond the dissertation): {runs} seeded runs per condition{' (quick)' if quick else ''}; "
        "mean ± 95 % CI (t) over seeds.",
        "",
        f"### Probabilistic sensorimotor embedding (9.4): gridworld {slip_size}x{slip_size}, slip 0.2",
        "",
        f"| estimator | Procrustes error | {scoring.HEADER} | samples per start (chosen) |",
        "|---|---|---|---|",
        f"| plain (one sampled trace per start) | {fmt(prob_ci['plain'], 4)} | {pcell('plain')} | 1 |",
        f"| mode of sampled traces | {fmt(prob_ci['mode'], 4)} | {pcell('mode')} | {fmt(samples['samples_mode'], 1)} |",
        f"| mean distance over sampled pairs | {fmt(prob_ci['mean'], 4)} | {pcell('mean')} "
        f"| {fmt(samples['samples_mean'], 1)} |",
        f"| mean distance, spread removed | {fmt(prob_ci['mean_debiased'], 4)} | {pcell('mean_debiased')} "
        "| same samples |",
        "",
        f"### Option discovery (9.6, Fig 9.3): {opt_size}x{opt_size} gridworld, goal in the far corner",
        "",
        f"Training steps (primitive world steps) until the greedy policy's mean steps to goal from 40 fixed "
        f"starts is <= {level:.1f} (1.25 x optimal); budget {budget} (runs that never reach it count as the budget).",
        "",
        "| agent | training steps to the level | reached |",
        "|---|---|---|",
    ]
    for a in AGENTS:
        t = steps_to_level[a]
        L.append(f"| {a} options | {t['mean']:.0f} ± {t['ci95']:.0f} | {t['reached']}/{runs} |")
    L += [
        "",
        f"Discovered options need {100 * saving:.0f} % fewer training steps than none. Welch t-test: "
        + ", ".join(f"{k}: p = {p:.3g}" for k, p in welch.items()),
        f"Discovered options (seed 0): {opts[0]['discovered_options']}; random (seed 0): {opts[0]['random_options']} "
        "(0 up, 1 down, 2 left, 3 right).",
        "",
        f"### Policy map of the mountain car (9.6, Fig 9.2): {pm_starts} random starts, Sarsa(λ) "
        f"trained {pm_train} steps, 5 k-means clusters of the 2-D embedding",
        "",
        "| seed | cluster sizes (majority outcome, purity) | outcomes with a cluster of their own |",
        "|---|---|---|",
    ]
    for m, cov in zip(maps, covered, strict=True):
        desc = ", ".join(f"{c['size']} ({c['majority']}, {c['purity']:.2f})" for c in m["clusters"])
        L.append(f"| {m['seed']} | {desc} | {', '.join(cov)} |")
    L += [
        "",
        "### Variations (9.5)",
        "",
        f"| gridworld | Procrustes, classical MDS | {scoring.HEADER}, MDS | Procrustes, Isomap (8 neighbours) "
        f"| {scoring.HEADER}, Isomap |",
        "|---|---|---|---|---|",
        f"| plain | {fmt(iso_ci[(False, 'mds')], 4)} | {icell(False, 'mds')} | {fmt(iso_ci[(False, 'isomap')], 4)} "
        f"| {icell(False, 'isomap')} |",
        f"| barrier | {fmt(iso_ci[(True, 'mds')], 4)} | {icell(True, 'mds')} | {fmt(iso_ci[(True, 'isomap')], 4)} "
        f"| {icell(True, 'isomap')} |",
        "",
        "| vergence starts | far starts sharing a goal step | far-half error, plain (rad) | state-aided (rad) | "
        f"Procrustes plain | state-aided | {scoring.HEADER}, plain | state-aided |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for v in verg:
        L.append(
            f"| {v['n_starts']} | {v['aliased_far_starts']} | {v['plain']['far_error_rad']:.5f} | "
            f"{v['state_aided']['far_error_rad']:.5f} | {v['plain']['procrustes']:.4f} | "
            f"{v['state_aided']['procrustes']:.4f} | {scoring.cell([v['plain']['scores']])} | "
            f"{scoring.cell([v['state_aided']['scores']])} |"
        )

    # figures
    m0 = maps[0]
    X, lab, outc = np.array(m0["coordinates"]), np.array(m0["labels"]), np.array(m0["outcomes"])

    def draw_map(axes: list) -> None:
        for c in range(lab.max() + 1):
            axes[0].scatter(*X[lab == c].T, s=6, label=f"cluster {c}")
        for o, col in zip(OUTCOMES, ("tab:red", "tab:green", "tab:blue"), strict=True):
            axes[1].scatter(*X[outc == o].T, s=6, c=col, label=o)
        axes[0].set(title="Policy map: clusters", xlabel="dim 1", ylabel="dim 2")
        axes[1].set(title="True outcome", xlabel="dim 1")
        for ax in axes:
            ax.legend(fontsize=7, markerscale=2)

    _figure(out, "policy_map.png", draw_map, ncols=2, width=10)

    def draw_options(axes: list) -> None:
        ax = axes[0]
        for a in AGENTS:
            grid = np.arange(500, budget + 1, 500)
            ys = []
            for r in opts:
                xs, ms = r[a]["steps"], r[a]["mean_steps"]
                ys.append([ms[min(np.searchsorted(xs, g), len(ms) - 1)] if ms else np.nan for g in grid])
            ax.plot(grid, np.nanmean(np.array(ys, dtype=float), axis=0), label=f"{a} options")
        ax.axhline(level, color="k", ls="--", lw=0.8, label="level")
        ax.set(title="Option discovery (Fig 9.3)", xlabel="training steps", ylabel="greedy steps to goal", yscale="log")
        ax.legend(fontsize=7)

    _figure(out, "options_learning.png", draw_options)

    def draw_bars(axes: list) -> None:
        names = ["plain", "mode", "mean"]
        axes[0].bar(names, [prob_ci[k][0] for k in names], yerr=[prob_ci[k][1] for k in names], color="tab:gray")
        axes[0].axhline(0.05, color="k", ls="--", lw=0.8)
        axes[0].set(title="Slip 0.2: Procrustes error", ylabel="Procrustes error")
        vv = verg[0]
        axes[1].bar(
            ["plain", "state-aided"],
            [vv["plain"]["far_error_rad"], vv["state_aided"]["far_error_rad"]],
            color=["tab:gray", "tab:green"],
        )
        axes[1].set(title="Vergence: far-half error", ylabel="rad")

    _figure(out, "probabilistic_and_state_aided.png", draw_bars, ncols=2, width=9)

    return {
        "probabilistic": {"results": prob, "ci95": prob_ci, "samples": samples},
        "options": {
            "level": level,
            "budget": budget,
            "steps_to_level": steps_to_level,
            "saving_vs_none": saving,
            "welch_p": welch,
            "results": opts,
        },
        "policy_map": {
            "clusters": m0["clusters"],
            "per_seed": [{"seed": m["seed"], "clusters": m["clusters"]} for m in maps],
            "outcomes_covered": covered,
        },
        "variations": {"isomap": iso, "state_aided": verg},
        "markdown": "\n".join(L),
    }
