"""Reaching with many action dimensions: a learned model of what each action does to a short state
vector (an arm's joint angles), the goal states met, and a plan that heads for one of them.

Why: an arm commanded in 6 or 7 joints cannot be learned through a discretised action table (3
values per joint are 3^7 = 2,187 actions, and a grid over 7 values has as many nodes per level of
detail), nor in a few thousand steps by an actor-critic. But its commands add up: a joint command
moves the state (the joint angles, which every real arm reports) by about the same amount wherever
the arm is. So the model is one mean displacement per action, fitted from every transition (a
handful of tries of each action fix it), and the goal is a place in that state: the goal states
met so far. The plan heads for their medoid (the one nearest all the others in steps), one action
at a time, each the action whose predicted move brings the state most steps nearer; equal moves
keep the action before, so the joints are moved one after another in a fixed order and a trace is
a function of its start (what the trace embedding needs). Until a goal state is met the actions
are random: a random walk of a 7-joint arm meets a goal a few lattice steps wide in about one
episode in sixteen.

Actions are rows of a table (a discrete space's, or a box space's per-axis moves, see
`agent.programs.generic_jobs.action_table`); the state is scaled to about [0, 1] by the caller.
The slow part (the model's fit and the medoid) is `plan_job`, a pure function of a snapshot, run
off the act path like the other learners' plans.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.agent.snapshot import rng_state, set_rng_state
from sensorimotor.protocol.params import option

#: learner=auto picks reach for action spaces of at least this many dimensions (a box's, or a
#: discrete space's pairs of +-moves) ...
MIN_ACTION_DIMS = 5
#: ... when a sensor is a vector of at most this many continuous values (the state it plans over)
MAX_STATE_VALUES = 16


@dataclass(frozen=True)
class ReachParams:
    """Parameters of the reach learner."""

    epsilon: float = option(0.05, "random-action rate once a goal state is known", min=0.0, max=1.0)
    ridge: float = option(1.0, "tries of zero displacement each action's mean move starts from", min=0.0)
    max_goals: int = option(4096, "distinct goal states remembered (the first met)", min=1)
    resolution: float = option(
        0.25, "predicted improvements closer than this (in steps) are ties (the model is no finer)", min=1e-6
    )
    keep: float = option(
        0.1,
        "the target stays while its summed distance to the goal states is within this fraction of the "
        "medoid's (a target that moves with every goal state met would change every trace)",
        min=0.0,
    )


def state_sensors(spec: Any) -> list[str]:
    """The sensors reach plans over: 1-D continuous vectors of at most `MAX_STATE_VALUES` values."""
    return [
        s.name
        for s in spec.sensors
        if len(s.shape) == 1 and np.dtype(s.dtype).kind == "f" and 0 < int(np.prod(s.shape)) <= MAX_STATE_VALUES
    ]


def fits(spec: Any) -> bool:
    """Whether learner=auto picks reach: many action dimensions and a short state vector."""
    a = spec.action_space
    dims = a.n // 2 if a.discrete else len(a.low)
    return dims >= MIN_ACTION_DIMS and bool(state_sensors(spec))


def medoid(goals: np.ndarray, scale: np.ndarray, current: np.ndarray | None = None, keep: float = 0.0) -> np.ndarray:
    """The goal state with the least summed distance (in steps, per-dimension `scale`) to the others;
    `current` instead while its own summed distance is within `keep` of that least one."""
    g = goals / scale
    cost = np.abs(g[:, None, :] - g[None, :, :]).sum(axis=(1, 2))
    best = int(np.argmin(cost))
    if current is not None:
        mine = float(np.abs(g - current / scale).sum())
        if mine <= (1.0 + keep) * float(cost[best]) + 1e-12:
            return current
    return goals[best]


def plan_job(
    counts: np.ndarray,
    sums: np.ndarray,
    goals: np.ndarray,
    ridge: float,
    target: np.ndarray | None = None,
    keep: float = 0.0,
) -> dict[str, Any]:
    """Fit each action's mean move and find the goal states' medoid, keeping `target` while it is
    nearly as central (a pure function, run off the act path). `scale` is each dimension's step: the
    largest move any action makes along it."""
    W = sums / (counts[:, None] + ridge)
    scale = np.abs(W).max(axis=0)
    scale = np.where(scale > 1e-9, scale, 1.0)
    target = medoid(goals, scale, target, keep) if len(goals) else None
    return {"W": W, "scale": scale, "target": target}


class ReachLearner:
    """Per-action mean moves of a state vector, the goal states met, and greedy steps to their medoid.

    Parameters
    ----------
    dims : int
        Values of the state vector.
    n_actions : int
        Rows of the action table.
    seed : int
        Seeds the exploration draws.
    params : ReachParams or None
        Its parameters (default `ReachParams()`).
    """

    plan_job = staticmethod(plan_job)

    def __init__(self, dims: int, n_actions: int, seed: int = 0, params: ReachParams | None = None) -> None:
        self.params = params or ReachParams()
        self.dims, self.n_actions = int(dims), int(n_actions)
        self.rng = np.random.default_rng(seed)
        self.plans = 0
        self.reset()

    def reset(self) -> None:
        """Forget every move and goal state (a changed body)."""
        self.counts = np.zeros(self.n_actions)
        self.sums = np.zeros((self.n_actions, self.dims))
        self.goals = np.zeros((0, self.dims))
        self._goal_keys: set[bytes] = set()
        self.W = np.zeros((self.n_actions, self.dims))
        self.scale = np.ones(self.dims)
        self.target: np.ndarray | None = None
        self.samples = 0

    # experience ----------------------------------------------------------------------------------
    def observe(self, x: np.ndarray, a: int, x2: np.ndarray, outcome: str) -> bool:
        """One transition (`outcome` as `agent.learners.model_planner.OUTCOMES`); True when a plan is
        due now: an action tried for the first time, or a goal state not met before."""
        x, x2 = np.asarray(x, dtype=np.float64), np.asarray(x2, dtype=np.float64)
        first = self.counts[a] == 0
        self.counts[a] += 1
        self.sums[a] += x2 - x
        self.samples += 1
        if outcome == "goal" and len(self.goals) < self.params.max_goals:
            key = np.round(x2, 6).tobytes()
            if key not in self._goal_keys:
                self._goal_keys.add(key)
                self.goals = np.vstack([self.goals, x2[None, :]])
                return True
        return bool(first)

    def job_args(self) -> dict[str, Any]:
        """Copies of the statistics for `plan_job`."""
        return {
            "counts": self.counts.copy(),
            "sums": self.sums.copy(),
            "goals": self.goals.copy(),
            "ridge": self.params.ridge,
            "target": None if self.target is None else self.target.copy(),
            "keep": self.params.keep,
        }

    def install(self, plan: dict[str, Any]) -> None:
        """Swap in a finished plan."""
        self.W, self.scale = np.asarray(plan["W"], dtype=np.float64), np.asarray(plan["scale"], dtype=np.float64)
        self.target = None if plan["target"] is None else np.asarray(plan["target"], dtype=np.float64)
        self.plans += 1

    # the policy ----------------------------------------------------------------------------------
    @property
    def w(self) -> np.ndarray:
        """The plan as one flat array (what sweeps follow and acceptance keeps copies of); the target
        is NaN while no goal state is known."""
        t = np.full(self.dims, np.nan) if self.target is None else self.target
        return np.concatenate([self.W.ravel(), self.scale, t])

    def q(self, x: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
        """Each action's predicted improvement, in steps toward the target (larger is better),
        rounded to `resolution`; all zero while no goal state is known."""
        if w is None:
            W, scale, target = self.W, self.scale, self.target
        else:
            w = np.asarray(w, dtype=np.float64)
            k = self.n_actions * self.dims
            W, scale, t = w[:k].reshape(self.n_actions, self.dims), w[k : k + self.dims], w[k + self.dims :]
            target = None if np.isnan(t).any() else t
        if target is None:
            return np.zeros(self.n_actions)
        x = np.asarray(x, dtype=np.float64)
        now = np.abs((target - x) / scale).sum()
        after = np.abs((target - x[None, :] - W) / scale).sum(axis=1)
        r = self.params.resolution
        return np.round((now - after) / r) * r

    def act(self, x: np.ndarray) -> int:
        """A random action until a goal state is known, then epsilon-greedy toward the target."""
        if self.target is None or self.rng.random() < self.params.epsilon:
            return int(self.rng.integers(self.n_actions))
        return int(np.argmax(self.q(x)))

    # saved state ---------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        return {
            "counts": self.counts.copy(),
            "sums": self.sums.copy(),
            "goals": self.goals.copy(),
            "W": self.W.copy(),
            "scale": self.scale.copy(),
            "target": None if self.target is None else self.target.copy(),
            "samples": self.samples,
            "plans": self.plans,
            "rng": rng_state(self.rng),
        }

    def restore(self, state: dict[str, Any]) -> None:
        self.counts = np.array(state["counts"], dtype=np.float64)
        self.sums = np.array(state["sums"], dtype=np.float64).reshape(self.n_actions, self.dims)
        self.goals = np.array(state["goals"], dtype=np.float64).reshape(-1, self.dims)
        self._goal_keys = {np.round(g, 6).tobytes() for g in self.goals}
        self.W = np.array(state["W"], dtype=np.float64).reshape(self.n_actions, self.dims)
        self.scale = np.array(state["scale"], dtype=np.float64)
        self.target = None if state["target"] is None else np.array(state["target"], dtype=np.float64)
        self.samples, self.plans = int(state["samples"]), int(state["plans"])
        set_rng_state(self.rng, state["rng"])


__all__ = [
    "MAX_STATE_VALUES",
    "MIN_ACTION_DIMS",
    "ReachLearner",
    "ReachParams",
    "fits",
    "medoid",
    "plan_job",
    "state_sensors",
]
