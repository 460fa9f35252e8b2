"""Model-based planning for low-dimensional continuous state: a locally linear model of how each
action moves the state, learned from experience, and value iteration over a grid of nodes with
multilinear interpolation of the value between nodes (Munos & Moore's interpolated dynamic
programming), optimistic about nodes never visited (R-max).

Why: a sparse goal in continuous state takes model-free learners (tile-coded Sarsa) a long time
to find and their greedy choices among near-equal actions are arbitrary, so traces of equal
starts differ. A model generalises across actions (a box action's effect is fitted as linear in
the action, per node, shrunk toward one fit of all samples), so a few samples of a node tell what
every action does there, and the plan is the shortest way to the goal under that model: traces
become a function of the start state, as the trace embedding needs.

States are scaled to [0, 1]^d by the caller; the grid has `grid` nodes per dimension. Cost 1 per
step (plus a tie-break of `effort` times the action's squared size), value 0 at the goal, a
failure costs as much as never arriving (1 / (1 - gamma)).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from sensorimotor.agent.snapshot import rng_state, set_rng_state

OUTCOMES = ("continue", "goal", "failure", "timeout")


def action_features(actions: np.ndarray, discrete: bool) -> np.ndarray:
    """The model's features of each action: one-hot (discrete) or the values and a constant (box),
    so a box action's displacement is fitted as linear in the action."""
    n = actions.shape[0]
    if discrete:
        return np.eye(n)
    return np.hstack([actions, np.ones((n, 1))])


def plan_job(
    A: np.ndarray,
    B: np.ndarray,
    visits: np.ndarray,
    goals: np.ndarray,
    fails: np.ndarray,
    landed: np.ndarray,
    landed_goal: np.ndarray,
    features: np.ndarray,
    grid: int,
    gamma: float,
    ridge: float,
    effort: np.ndarray,
    value: np.ndarray | None,
    exploit: np.ndarray | None = None,
    max_iterations: int = 300,
) -> dict[str, Any]:
    """Fit the model and run value iteration (a pure function, run off the act path).

    Returns the node values `U` (cost-to-go of landing at a node: 0 at the goal), the per-node
    linear model `W` [nodes, features, dims], the goal and failure probabilities of each (node,
    action) `pg`, `pf`, `V` (the values before the goal discount, to warm-start the next plan) and
    the iterations done."""
    n_nodes, p, d = B.shape
    eye = np.eye(p)
    Wg = np.linalg.solve(A.sum(axis=0) + ridge * eye, B.sum(axis=0))  # one fit of all samples: the prior
    W = np.linalg.solve(A + ridge * eye[None], B + ridge * Wg[None])  # per node, shrunk toward the prior
    nodes = node_points(grid, d)
    step = np.einsum("ap,npd->nad", features, W)  # predicted displacement of each action at each node
    idx, wts = interpolation(nodes[:, None, :] + step, grid)  # (n, a, 2^d)
    seen = np.maximum(visits, 1)
    pg, pf = goals / seen, fails / seen
    s = landed_goal / np.maximum(landed, 1)
    known = landed + visits.sum(axis=1) > 0
    v_fail = 1.0 / (1.0 - gamma)
    go_on = np.clip(1.0 - pg - pf, 0.0, 1.0)

    def iterate(V: np.ndarray, unknown: float) -> tuple[np.ndarray, np.ndarray, int]:
        done = 0
        for done in range(1, max_iterations + 1):  # noqa: B007 - the count is returned
            U = np.where(known, (1.0 - s) * V, unknown)
            Q = effort[None, :] + 1.0 + gamma * (go_on * (wts * U[idx]).sum(axis=2) + pf * v_fail)
            Vn = np.where(known, Q.min(axis=1), unknown)
            change = float(np.abs(Vn - V).max())
            V = Vn
            if change < 1e-4:
                break
        return V, np.where(known, (1.0 - s) * V, unknown), done

    # learning: nodes never met cost nothing (R-max: the plan goes to find out); the policy that is
    # swept and embedded: they cost as much as never arriving (it keeps to what it knows)
    V, U, done = iterate(np.zeros(n_nodes) if value is None else np.array(value, dtype=np.float64), 0.0)
    start = np.full(n_nodes, v_fail) if exploit is None else np.array(exploit, dtype=np.float64)
    Ve, Ue, done_e = iterate(start, v_fail)
    return {
        "U": U,
        "Ue": Ue,
        "W": W,
        "pg": pg,
        "pf": pf,
        "V": V,
        "Ve": Ve,
        "known": known,
        "iterations": done + done_e,
    }


def node_points(grid: int, d: int) -> np.ndarray:
    """The grid's nodes in [0, 1]^d, in C order: (grid^d, d)."""
    axis = np.linspace(0.0, 1.0, grid)
    return np.array(list(itertools.product(axis, repeat=d)), dtype=np.float64).reshape(-1, d)


def node_of(x: np.ndarray, grid: int) -> int:
    """The nearest node of a scaled state."""
    i = np.clip(np.rint(np.clip(x, 0.0, 1.0) * (grid - 1)), 0, grid - 1).astype(np.int64)
    return int(np.ravel_multi_index(tuple(i), (grid,) * x.size))


def interpolation(points: np.ndarray, grid: int) -> tuple[np.ndarray, np.ndarray]:
    """Multilinear interpolation of points [..., d] (clipped to the grid): the 2^d node indices and
    weights of each."""
    d = points.shape[-1]
    g = np.clip(points, 0.0, 1.0) * (grid - 1)
    base = np.minimum(np.floor(g), grid - 2).astype(np.int64)
    t = g - base
    corners = np.array(list(itertools.product((0, 1), repeat=d)), dtype=np.int64)  # (2^d, d)
    ix = base[..., None, :] + corners  # (..., 2^d, d)
    w = np.prod(np.where(corners == 1, t[..., None, :], 1.0 - t[..., None, :]), axis=-1)
    strides = grid ** np.arange(d - 1, -1, -1)
    return (ix * strides).sum(axis=-1), w


class ModelPlanner:
    """Experience statistics, the installed plan, and greedy one-step lookahead on it.

    Parameters
    ----------
    dims : int
        State dimensions (scaled to [0, 1] by the caller).
    actions : np.ndarray
        The action table [n_actions, action_dims].
    discrete : bool
        Whether the actions are a discrete space's (then fitted one by one, not as linear).
    grid : int
        Nodes per dimension.
    gamma : float
        Discount (a failure costs 1 / (1 - gamma)).
    epsilon : float
        Probability of a random action while learning.
    ridge : float
        How strongly each node's model is shrunk toward the fit of all samples (in samples).
    effort : float
        Cost of an action per unit of its squared size (relative to the largest): among equally
        quick actions the smaller is chosen, so traces are a function of the start.
    seed : int
        Seeds the exploration draws.
    """

    def __init__(
        self,
        dims: int,
        actions: np.ndarray,
        discrete: bool,
        grid: int,
        gamma: float = 0.99,
        epsilon: float = 0.05,
        ridge: float = 2.0,
        effort: float = 0.01,
        seed: int = 0,
    ) -> None:
        if grid < 2:
            raise ValueError("grid needs at least 2 nodes per dimension")
        self.dims, self.grid, self.gamma, self.epsilon, self.ridge = dims, grid, gamma, epsilon, ridge
        self.actions = np.asarray(actions, dtype=np.float64)
        self.discrete = discrete
        self.n_actions = self.actions.shape[0]
        self.features = action_features(self.actions, discrete)
        size = np.square(self.actions).sum(axis=1)
        self.effort = effort * (size / size.max() if not discrete and size.max() > 0 else np.zeros(self.n_actions))
        self.n_nodes = grid**dims
        self.rng = np.random.default_rng(seed)
        self.plans = 0
        self.reset()

    def reset(self) -> None:
        """Forget all experience and the plan (a changed body)."""
        p = self.features.shape[1]
        n = self.n_nodes
        self.A = np.zeros((n, p, p))
        self.B = np.zeros((n, p, self.dims))
        self.visits = np.zeros((n, self.n_actions))
        self.goals = np.zeros((n, self.n_actions))
        self.fails = np.zeros((n, self.n_actions))
        self.landed = np.zeros(n)
        self.landed_goal = np.zeros(n)
        self.known = np.zeros(n, dtype=bool)  # nodes with experience (R-max: the others are optimistic)
        self.plan_known = np.zeros(n, dtype=bool)  # the same when the installed plan was made
        self.U = np.zeros(n)
        self.Ue = np.zeros(n)  # the same without optimism: the policy that is swept
        self.V: np.ndarray | None = None
        self.Ve: np.ndarray | None = None
        self.W = np.zeros((n, p, self.dims))
        self.pg = np.zeros((n, self.n_actions))
        self.pf = np.zeros((n, self.n_actions))
        self.samples = 0

    # experience ------------------------------------------------------------------------------
    def observe(self, x: np.ndarray, a: int, x2: np.ndarray, outcome: str) -> bool:
        """One transition: state `x`, action `a`, next state `x2`, how it ended (`OUTCOMES`).
        True when it is the first experience of a node (time for a new plan, as R-max replans)."""
        i = node_of(x, self.grid)
        f = self.features[a]
        self.A[i] += np.outer(f, f)
        self.B[i] += np.outer(f, np.asarray(x2, dtype=np.float64) - x)
        self.visits[i, a] += 1
        if outcome == "goal":
            self.goals[i, a] += 1
        elif outcome == "failure":
            self.fails[i, a] += 1
        j = node_of(np.asarray(x2, dtype=np.float64), self.grid)
        self.landed[j] += 1
        self.landed_goal[j] += outcome == "goal"
        self.samples += 1
        new = not (self.known[i] and self.known[j])
        self.known[i] = self.known[j] = True
        return new

    def job_args(self) -> dict[str, Any]:
        """Copies of the statistics for `plan_job`."""
        return {
            "A": self.A.copy(),
            "B": self.B.copy(),
            "visits": self.visits.copy(),
            "goals": self.goals.copy(),
            "fails": self.fails.copy(),
            "landed": self.landed.copy(),
            "landed_goal": self.landed_goal.copy(),
            "features": self.features,
            "grid": self.grid,
            "gamma": self.gamma,
            "ridge": self.ridge,
            "effort": self.effort,
            "value": None if self.V is None else self.V.copy(),
            "exploit": None if self.Ve is None else self.Ve.copy(),
        }

    def install(self, plan: dict[str, Any]) -> None:
        """Swap in a finished plan."""
        self.U, self.W = np.asarray(plan["U"]), np.asarray(plan["W"])
        self.pg, self.pf, self.V = np.asarray(plan["pg"]), np.asarray(plan["pf"]), np.asarray(plan["V"])
        self.plan_known = np.asarray(plan["known"], dtype=bool)
        self.Ue, self.Ve = np.asarray(plan["Ue"]), np.asarray(plan["Ve"])
        self.plans += 1

    # the policy ------------------------------------------------------------------------------
    @property
    def w(self) -> np.ndarray:
        """The plan without optimism as one flat array: the policy the program sweeps, embeds and
        keeps copies of (accepted policies)."""
        return np.concatenate([self.Ue.ravel(), self.W.ravel(), self.pg.ravel(), self.pf.ravel()])

    def _unpack(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n, na, p, d = self.n_nodes, self.n_actions, self.features.shape[1], self.dims
        U = w[:n]
        W = w[n : n + n * p * d].reshape(n, p, d)
        o = n + n * p * d
        return U, W, w[o : o + n * na].reshape(n, na), w[o + n * na : o + 2 * n * na].reshape(n, na)

    def q(self, x: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
        """Negated one-step lookahead costs of every action at `x` (larger is better, as Q values).
        While learning (`w` None), a node met since the plan was made is no longer optimistic: it
        costs one step more than this node until the next plan values it."""
        U, W, pg, pf = (self.U, self.W, self.pg, self.pf) if w is None else self._unpack(np.asarray(w))
        x = np.asarray(x, dtype=np.float64)
        i = node_of(x, self.grid)
        if w is None:
            U = np.where(self.known & ~self.plan_known, U[i] + 1.0, U)
        nxt = x[None, :] + self.features @ W[i]
        idx, wts = interpolation(nxt, self.grid)
        go_on = np.clip(1.0 - pg[i] - pf[i], 0.0, 1.0)
        cost = self.effort + 1.0 + self.gamma * (go_on * (wts * U[idx]).sum(axis=1) + pf[i] / (1.0 - self.gamma))
        return -cost

    def act(self, x: np.ndarray) -> int:
        """Epsilon-greedy on the lookahead."""
        if self.epsilon > 0 and self.rng.random() < self.epsilon:
            return int(self.rng.integers(self.n_actions))
        return int(np.argmax(self.q(x)))

    # saved state -----------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        names = (
            "A",
            "B",
            "visits",
            "goals",
            "fails",
            "landed",
            "landed_goal",
            "U",
            "Ue",
            "W",
            "pg",
            "pf",
            "known",
            "plan_known",
        )
        out: dict[str, Any] = {k: getattr(self, k).copy() for k in names}
        out.update(V=None if self.V is None else self.V.copy(), samples=self.samples, plans=self.plans)
        out["Ve"] = None if self.Ve is None else self.Ve.copy()
        out["rng"] = rng_state(self.rng)
        return out

    def restore(self, state: dict[str, Any]) -> None:
        for k in ("A", "B", "visits", "goals", "fails", "landed", "landed_goal", "U", "Ue", "W", "pg", "pf"):
            setattr(self, k, np.array(state[k], dtype=np.float64))
        self.known = np.array(state["known"], dtype=bool)
        self.plan_known = np.array(state["plan_known"], dtype=bool)
        self.V = None if state.get("V") is None else np.array(state["V"], dtype=np.float64)
        self.Ve = None if state.get("Ve") is None else np.array(state["Ve"], dtype=np.float64)
        self.samples, self.plans = int(state["samples"]), int(state["plans"])
        set_rng_state(self.rng, state["rng"])


__all__ = ["OUTCOMES", "ModelPlanner", "action_features", "interpolation", "node_of", "node_points", "plan_job"]
