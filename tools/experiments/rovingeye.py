"""The roving eye experiment of ch. 5.2 (Table 5.1, Fig 5.8, Fig 5.11), as pure functions.

On the same points of the largest goal region, five ways of making a map of where the eye is:
MDS on the raw eye pixels (the sensor baseline), and sensorimotor embedding of the traces of four
policies that bring the eye to the perceptual goal - the gradient policy, epsilon-gradient (15 %
random moves, the best-scoring of several samples), a near-optimal hand-coded policy, and a learned
ballistic policy (the ch. 4 stochastic estimator, `SaccadeLearner`, one field per start point).
Each: traces -> trace distances (padded sum, Eq 3.1) -> classical MDS -> Procrustes error against
the true eye offsets, and the mean score (end reward discounted by the number of actions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import cdist

from sensorimotor.agent.embedding import classical_mds, procrustes, trace_distances
from sensorimotor.agent.learners.saccade import SaccadeLearner
from sensorimotor.worlds.perceptual_goals import IntensitySurface, directions, gradient_step, reward, score
from sensorimotor.worlds.roving_eye import eye_bounds, eye_view, image_goals, load_image

METHODS = ("sensor_mds", "gradient", "epsilon_gradient", "hand_coded", "ballistic")
LABELS = {
    "sensor_mds": "MDS (sensor)",
    "gradient": "gradient",
    "epsilon_gradient": "ε-gradient",
    "hand_coded": "hand-coded",
    "ballistic": "ballistic",
}
#: Table 5.1 of the dissertation: Procrustes error and score per method (sensor MDS has no score)
DISSERTATION_ERROR = {
    "sensor_mds": 0.80,
    "gradient": 0.20,
    "epsilon_gradient": 0.11,
    "hand_coded": 0.05,
    "ballistic": 0.01,
}
DISSERTATION_SCORE = {"gradient": 0.35, "epsilon_gradient": 0.51, "hand_coded": 0.62, "ballistic": 0.67}


@dataclass(frozen=True)
class Config:
    """The experiment's settings (the world's defaults where they overlap)."""

    image: str = "camera"
    eye_px: int = 128
    sigma_px: float = 16.0
    grid_px: float = 4.0
    step_px: float = 5.0
    n_points: int = 100
    reward_px: float = 5.0
    discount: float = 0.9
    epsilon: float = 0.15
    samples: int = 200  # epsilon-gradient trajectories per point; the best-scoring is kept
    max_steps: int = 120
    trials: int = 300  # ballistic training jumps per point
    alpha: float = 0.5
    noise_start_px: float = 16.0  # ballistic exploration noise, annealed geometrically ...
    noise_end_px: float = 0.2  # ... to this
    max_jump_px: float = 192.0


@dataclass(frozen=True)
class Setup:
    """The image, its intensity surface, the goal of the largest region and the sampled points."""

    image: np.ndarray
    surface: IntensitySurface
    goal: np.ndarray  # [2]
    points: np.ndarray  # [n, 2] eye offsets (u, v): the truth
    lo: np.ndarray
    hi: np.ndarray


@dataclass(frozen=True)
class MethodResult:
    """One method's map: its Procrustes error, mean score, MDS spectrum and coordinates."""

    method: str
    error: float
    score: float | None
    eigenvalues: np.ndarray  # descending, the first ten
    coordinates: np.ndarray  # [n, 2] aligned onto the standardised truth
    mean_actions: float | None


def setup(cfg: Config, seed: int) -> Setup:
    """The image and goals (fixed per image) and `n_points` points drawn from the largest region."""
    img = load_image(cfg.image)
    lo, hi = eye_bounds(img, cfg.eye_px)
    goals = image_goals(cfg.image, cfg.eye_px, cfg.sigma_px, cfg.grid_px, cfg.step_px)
    g = goals.largest()
    region = goals.region(g)
    rng = np.random.default_rng(seed)
    pts = region[rng.choice(len(region), min(cfg.n_points, len(region)), replace=False)]
    return Setup(img, IntensitySurface.of(img, cfg.sigma_px), goals.centres[g].copy(), pts, lo, hi)


def _rollout(
    s: Setup, cfg: Config, starts: np.ndarray, policy, rng: np.random.Generator | None = None, eps: float = 0.0
) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Run a discrete policy from every start at once. `policy(pos) -> index or -1 (stop)`. With
    `eps`, each step is a random move with that probability (a stop is only taken greedily).
    Returns the traces (each [L, 2] of moves, px), end points and numbers of actions."""
    dirs = directions(16)
    pos = np.array(starts, dtype=np.float64)
    n = len(pos)
    moves = np.full((n, cfg.max_steps), -1, dtype=np.int64)
    count = np.zeros(n, dtype=np.int64)
    live = np.ones(n, dtype=bool)
    for t in range(cfg.max_steps):
        idx = np.flatnonzero(live)
        if idx.size == 0:
            break
        k = policy(pos[idx])
        if eps > 0 and rng is not None:
            rnd = rng.random(idx.size) < eps
            k = np.where(rnd, rng.integers(0, 16, idx.size), k)
        go = k >= 0
        live[idx[~go]] = False
        j, kj = idx[go], k[go]
        pos[j] = pos[j] + cfg.step_px * dirs[kj]
        moves[j, t] = kj
        count[j] += 1
    traces = [cfg.step_px * dirs[moves[i, : count[i]]] for i in range(n)]
    return traces, pos, count


def gradient_policy(s: Setup, cfg: Config):
    """The gradient policy on the directional filters (stops at a local maximum)."""
    dirs = directions(16)
    return lambda pos: gradient_step(s.surface, pos, dirs, cfg.step_px)


def hand_coded_policy(s: Setup, cfg: Config):
    """Near-optimal hand-coded policy (it knows where the goal is): the move that begins the best
    pair of moves (or single move) toward the goal, until no move or pair brings the eye closer."""
    dirs = cfg.step_px * directions(16)
    pairs = np.concatenate([dirs, (dirs[:, None, :] + dirs[None, :, :]).reshape(-1, 2)])  # 16 singles, 256 pairs
    first = np.concatenate([np.arange(16), np.repeat(np.arange(16), 16)])

    def policy(pos: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(pos[:, None, :] + pairs[None, :, :] - s.goal, axis=2)
        best = np.argmin(d, axis=1)
        now = np.linalg.norm(pos - s.goal, axis=1)
        return np.where(d[np.arange(len(pos)), best] < now - 1e-9, first[best], -1)

    return policy


def _scores(s: Setup, cfg: Config, ends: np.ndarray, count: np.ndarray) -> np.ndarray:
    return score(np.linalg.norm(ends - s.goal, axis=1), count, cfg.reward_px, cfg.discount)


def gradient_traces(s: Setup, cfg: Config) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Traces, scores and action counts of the gradient policy from every point."""
    traces, ends, count = _rollout(s, cfg, s.points, gradient_policy(s, cfg))
    return traces, _scores(s, cfg, ends, count), count


def epsilon_gradient_traces(s: Setup, cfg: Config, seed: int) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """epsilon-gradient: `samples` trajectories per point with `epsilon` random moves; the
    highest-scoring one of each point is kept."""
    rng = np.random.default_rng(seed)
    n = len(s.points)
    starts = np.repeat(s.points, cfg.samples, axis=0)
    traces, ends, count = _rollout(s, cfg, starts, gradient_policy(s, cfg), rng, cfg.epsilon)
    sc = _scores(s, cfg, ends, count).reshape(n, cfg.samples)
    best = np.argmax(sc, axis=1)
    pick = np.arange(n) * cfg.samples + best
    return [traces[i] for i in pick], sc[np.arange(n), best], count[pick]


def hand_coded_traces(s: Setup, cfg: Config) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Traces, scores and action counts of the hand-coded policy."""
    traces, ends, count = _rollout(s, cfg, s.points, hand_coded_policy(s, cfg))
    return traces, _scores(s, cfg, ends, count), count


def learn_ballistic(s: Setup, cfg: Config, seed: int, gain: float = 1.0) -> SaccadeLearner:
    """The ch. 4 stochastic estimator learning one jump per point: each point is a field that is
    active (1) when the eye starts there; the reward is the world's end reward. Exploration noise
    is annealed from `noise_start_px` to `noise_end_px` over the training jumps."""
    n = len(s.points)
    m = cfg.max_jump_px
    learner = SaccadeLearner(
        n,
        np.array([-m, -m]),
        np.array([m, m]),
        alpha=cfg.alpha,
        rule="robust",
        exploration="gaussian",
        init_spread=0.0,
        seed=seed,
    )
    rng = np.random.default_rng(seed + 1)
    total = cfg.trials * n
    noise = np.geomspace(cfg.noise_start_px, cfg.noise_end_px, total)
    delta = np.zeros(n)
    for t in range(total):
        i = int(rng.integers(n))
        delta[:] = 0.0
        delta[i] = 1.0
        learner.noise_sd = float(noise[t])
        a = learner.act(delta)
        end = s.points[i] + gain * a
        learner.learn_one(delta, a, float(reward(np.linalg.norm(end - s.goal), cfg.reward_px)))
    return learner


def ballistic_traces(s: Setup, cfg: Config, seed: int) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """One-jump traces of the learned ballistic policy (greedy), their scores and action counts."""
    learner = learn_ballistic(s, cfg, seed)
    jumps = learner.pi.copy()
    ends = s.points + jumps
    count = np.ones(len(s.points), dtype=np.int64)
    return [j[None, :] for j in jumps], _scores(s, cfg, ends, count), count


def embed(
    D: np.ndarray, truth: np.ndarray, method: str, sc: np.ndarray | None, count: np.ndarray | None
) -> MethodResult:
    """Classical MDS (2-D) of the distances `D`, scored by Procrustes against `truth`."""
    res = classical_mds(np.asarray(D, dtype=np.float64), k=2, method="full")
    pr = procrustes(truth, res.coordinates)
    return MethodResult(
        method,
        pr.disparity,
        None if sc is None else float(np.mean(sc)),
        np.asarray(res.eigenvalues[:10], dtype=np.float64),
        pr.aligned,
        None if count is None else float(np.mean(count)),
    )


def sensor_distances(s: Setup, eye_px: int) -> np.ndarray:
    """Pixel distances between the eye's views at the points (the sensor baseline)."""
    views = np.stack([eye_view(s.image, p, eye_px).ravel() for p in s.points])
    return cdist(views, views)


def run(cfg: Config, seed: int) -> dict[str, MethodResult]:
    """All five methods on the same `n_points` points (drawn with `seed`)."""
    s = setup(cfg, seed)
    out = {"sensor_mds": embed(sensor_distances(s, cfg.eye_px), s.points, "sensor_mds", None, None)}
    for name, (traces, sc, count) in (
        ("gradient", gradient_traces(s, cfg)),
        ("epsilon_gradient", epsilon_gradient_traces(s, cfg, seed)),
        ("hand_coded", hand_coded_traces(s, cfg)),
        ("ballistic", ballistic_traces(s, cfg, seed)),
    ):
        out[name] = embed(trace_distances(traces), s.points, name, sc, count)
    return out


def truth_standardised(points: np.ndarray) -> np.ndarray:
    """The truth as Procrustes standardises it (centred, unit norm): the frame of `coordinates`."""
    X = points - points.mean(axis=0)
    return X / np.linalg.norm(X)
