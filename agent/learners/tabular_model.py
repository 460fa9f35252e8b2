"""Model-based learning over a table of states: count where each (state, action) led, plan on the
counted model by value iteration, and explore by optimism about what was not tried enough (R-max,
Brafman & Tennenholtz 2002).

Why: a table is a model that is cheap to learn. Random exploration (what LSPI samples from) dies in
the first hole of a lake or wanders a large room for thousands of steps before it meets the goal
once; optimism sends the agent straight to the nearest untried action, so every (state, action) is
tried after about as many steps as there are of them. A stochastic world is handled by
construction: the counts estimate its transition probabilities, and the plan maximises the
discounted chance of reaching the goal (a long horizon: the safe way round, not the short risky
one).

Values: Q(s, a) = P(goal | s, a) + gamma * sum_s' P(s' | s, a) V(s'), V(s) = max_a Q(s, a); a
failure (a termination that is not the goal) is worth 0, as never arriving. In a deterministic world
Q is gamma^(steps to the goal - 1): the greedy policy takes the shortest way. The *exploit* values
(`q`, what sweeps follow) count only what was seen; the *explore* values count an action tried fewer
than `known` times as reaching the goal at once.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import scipy.sparse as sp

from sensorimotor.agent.snapshot import rng_state, set_rng_state

OUTCOMES = ("continue", "goal", "failure")


def plan_tabular_job(
    n_states: int,
    n_actions: int,
    rows: np.ndarray,
    cols: np.ndarray,
    counts: np.ndarray,
    tried: np.ndarray,
    goals: np.ndarray,
    gamma: float,
    known: int,
    tolerance: float = 1e-7,
    max_iterations: int = 5000,
) -> dict[str, Any]:
    """Value iteration on the counted model (a pure function, run off the act path).

    `rows`/`cols`/`counts`: how often (state * n_actions + action) led to a state that goes on;
    `tried`: how often each (state, action) was taken; `goals`: how often it reached the goal.
    Returns the exploit values `q` and the explore values `q_explore` ([n_states, n_actions]), the
    sweeps value iteration took."""
    S, A = int(n_states), int(n_actions)
    n = np.asarray(tried, dtype=np.float64).reshape(S * A)
    safe = np.maximum(n, 1.0)
    r = np.asarray(rows, dtype=np.int64)
    P = sp.csr_matrix(
        (np.asarray(counts, dtype=np.float64) / safe[r], (r, np.asarray(cols, dtype=np.int64))), shape=(S * A, S)
    )
    pg = np.asarray(goals, dtype=np.float64).reshape(S * A) / safe
    unknown = n < max(1, int(known))

    def solve(optimistic: bool) -> tuple[np.ndarray, int]:
        V = np.zeros(S)
        it = 0
        for it in range(1, max_iterations + 1):  # noqa: B007 - the count is returned
            Q = pg + gamma * (P @ V)
            if optimistic:
                Q = np.where(unknown, 1.0, Q)
            V_new = Q.reshape(S, A).max(axis=1)
            change = float(np.abs(V_new - V).max()) if S else 0.0
            V = V_new
            if change <= tolerance:
                break
        Q = pg + gamma * (P @ V)
        if optimistic:
            Q = np.where(unknown, 1.0, Q)
        return Q.reshape(S, A), it

    q, it_exploit = solve(False)
    q_explore, it_explore = solve(True)
    return {"q": q, "q_explore": q_explore, "iterations": max(it_exploit, it_explore)}


class TabularModel:
    """A counted transition and goal model over `n_states` x `n_actions`, planned on by value
    iteration (`plan_tabular_job`, run by the caller off the act path and swapped in with
    `install`); `act` explores, `q` is the greedy policy's values.

    `known`: tries after which an action's outcomes are trusted (1 in a deterministic world; the
    caller raises it to `known_stochastic` with `set_stochastic`). `epsilon`: the rate of random
    actions while exploring, once nothing near is untried. Implements
    `agent.learners.base.TableLearner`."""

    plan_job: ClassVar[Any] = staticmethod(plan_tabular_job)

    def __init__(
        self,
        n_states: int,
        n_actions: int,
        gamma: float = 0.99,
        known: int = 1,
        known_stochastic: int = 10,
        epsilon: float = 0.05,
        seed: int = 0,
    ) -> None:
        if n_states < 1 or n_actions < 1:
            raise ValueError(f"a table needs states and actions, not {n_states} x {n_actions}")
        if not 0.0 < gamma < 1.0:
            raise ValueError(f"gamma must be in (0, 1), not {gamma}")
        if known < 1 or known_stochastic < known:
            raise ValueError(f"known tries must satisfy 1 <= known ({known}) <= known_stochastic ({known_stochastic})")
        if not 0.0 <= epsilon <= 1.0:
            raise ValueError(f"epsilon must be in [0, 1], not {epsilon}")
        self.n_states, self.n_actions = int(n_states), int(n_actions)
        self.gamma, self.epsilon = float(gamma), float(epsilon)
        self.known_deterministic, self.known_stochastic = int(known), int(known_stochastic)
        self.known = self.known_deterministic
        self.rng = np.random.default_rng(seed)
        self.reset()

    def reset(self) -> None:
        """Forget the model and the plan (the body changed)."""
        S, A = self.n_states, self.n_actions
        self.tried = np.zeros((S, A), dtype=np.int64)
        self.goals = np.zeros((S, A), dtype=np.int64)
        self._next: dict[tuple[int, int], int] = {}  # (state * A + action, next state) -> count
        self._likely: dict[int, int] = {}  # state * A + action -> its most frequent next state that goes on
        self._path: list[tuple[int, int]] = []  # (action, the state it is taken in) to the nearest untried
        self._exhausted = False  # no untried action is reachable (until a new outcome or state is met)
        self.q = np.zeros((S, A))
        self.q_explore = np.ones((S, A))
        self.plans = 0
        self._path = []
        self._exhausted = False

    @property
    def n_transitions(self) -> int:
        return int(self.tried.sum())

    def set_stochastic(self, stochastic: bool) -> None:
        """A stochastic world asks for more tries before an action's outcomes are trusted."""
        self.known = self.known_stochastic if stochastic else self.known_deterministic
        self._exhausted = False

    def learn_one(self, s: int, a: int, s_next: int | None, outcome: str) -> bool:
        """Count one transition: (s, a) led to `s_next` (the episode goes on, or was cut by a time
        limit), to the goal, or to a failure. True when (s, a) has just become known (a plan would
        now differ)."""
        if outcome not in OUTCOMES:
            raise ValueError(f"outcome {outcome!r}: one of {', '.join(OUTCOMES)}")
        self.tried[s, a] += 1
        if outcome == "goal":
            self.goals[s, a] += 1
        elif outcome == "continue":
            if s_next is None:
                raise ValueError("a transition that goes on needs its next state")
            sa = s * self.n_actions + a
            key = (sa, int(s_next))
            n = self._next.get(key, 0) + 1
            if n == 1:
                self._exhausted = False  # a new way, maybe to a state with untried actions
            self._next[key] = n
            best = self._likely.get(sa)
            if best is None or best != s_next and n > self._next[(sa, best)]:
                self._likely[sa] = int(s_next)
        return bool(self.tried[s, a] == self.known)

    def complete(self) -> bool:
        """Every action of every state met was tried `known` times."""
        met = self.tried.sum(axis=1) > 0
        return not bool((self.tried[met] < self.known).any())

    def untried(self, s: int) -> np.ndarray:
        """The actions of `s` tried fewer than `known` times."""
        return np.flatnonzero(self.tried[s] < self.known)

    def act(self, s: int) -> int:
        """An exploring action: an untried one of this state (at random); else the next step of the
        shortest known way to the nearest state with an untried action (breadth-first over the most
        frequent outcome of each action: the plan is swapped in late, this is now); else at rate
        `epsilon` a random one, or the greedy one on the optimistic plan."""
        todo = self.untried(s)
        if todo.size:
            self._path = []
            return int(todo[self.rng.integers(todo.size)])
        if (not self._path or self._path[0][1] != s) and not self._exhausted:
            self._path = self._way_to_untried(s)
            self._exhausted = not self._path
        if self._path:
            return self._path.pop(0)[0]
        if self.rng.random() < self.epsilon:
            return int(self.rng.integers(self.n_actions))
        q = self.q_explore[s]
        best = np.flatnonzero(q >= q.max() - 1e-12)
        return int(best[self.rng.integers(best.size)])

    def _way_to_untried(self, s: int) -> list[tuple[int, int]]:
        """The shortest way (breadth-first over known outcomes) from `s` to a state with an untried
        action: [(action, state it is taken in), ...]; [] when none is reachable."""
        A = self.n_actions
        frontier = self.tried.min(axis=1) < self.known
        came: dict[int, tuple[int, int]] = {s: (-1, -1)}
        queue = [s]
        for u in queue:
            for a in range(A):
                v = self._likely.get(u * A + a)
                if v is None or v in came:
                    continue
                came[v] = (u, a)
                if frontier[v]:
                    path = []
                    while v != s:
                        u_, a_ = came[v]
                        path.append((a_, u_))
                        v = u_
                    return path[::-1]
                queue.append(v)
        return []

    def job_args(self) -> dict[str, Any]:
        """A snapshot of the model for `plan_tabular_job`."""
        keys = np.array(list(self._next.keys()), dtype=np.int64).reshape(-1, 2)
        return {
            "n_states": self.n_states,
            "n_actions": self.n_actions,
            "rows": keys[:, 0].copy(),
            "cols": keys[:, 1].copy(),
            "counts": np.array(list(self._next.values()), dtype=np.int64),
            "tried": self.tried.copy(),
            "goals": self.goals.copy(),
            "gamma": self.gamma,
            "known": self.known,
        }

    def install(self, result: dict[str, Any]) -> None:
        """Swap in a plan made by `plan_tabular_job`."""
        self.q = np.asarray(result["q"], dtype=np.float64).reshape(self.n_states, self.n_actions)
        self.q_explore = np.asarray(result["q_explore"], dtype=np.float64).reshape(self.n_states, self.n_actions)
        self.plans += 1

    def state(self) -> dict[str, Any]:
        args = self.job_args()
        return {
            "rows": args["rows"],
            "cols": args["cols"],
            "counts": args["counts"],
            "tried": self.tried.copy(),
            "goals": self.goals.copy(),
            "q": self.q.copy(),
            "q_explore": self.q_explore.copy(),
            "plans": self.plans,
            "known": self.known,
            "path": [list(p) for p in self._path],
            "exhausted": self._exhausted,
            "rng": rng_state(self.rng),
        }

    def restore(self, state: dict[str, Any]) -> None:
        shape = (self.n_states, self.n_actions)
        tried = np.asarray(state["tried"], dtype=np.int64)
        if tried.shape != shape:
            raise ValueError(f"saved model is {tried.shape}, this table {shape}")
        self.tried, self.goals = tried, np.asarray(state["goals"], dtype=np.int64).reshape(shape)
        rows, cols = np.asarray(state["rows"], dtype=np.int64), np.asarray(state["cols"], dtype=np.int64)
        counts = np.asarray(state["counts"], dtype=np.int64)
        self._next = {(int(r), int(c)): int(n) for r, c, n in zip(rows, cols, counts, strict=True)}
        self._likely = {}
        for (sa, nxt), n in self._next.items():  # the most frequent; the first met among equals, as counted
            best = self._likely.get(sa)
            if best is None or n > self._next[(sa, best)]:
                self._likely[sa] = nxt
        self._path = [(int(a), int(u)) for a, u in state.get("path", [])]
        self._exhausted = bool(state.get("exhausted", False))
        self.q = np.asarray(state["q"], dtype=np.float64).reshape(shape)
        self.q_explore = np.asarray(state["q_explore"], dtype=np.float64).reshape(shape)
        self.plans = int(state["plans"])
        self.known = int(state["known"])
        set_rng_state(self.rng, state["rng"])


__all__ = ["OUTCOMES", "TabularModel", "plan_tabular_job"]
