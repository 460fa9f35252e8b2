"""Least-squares policy iteration (Lagoudakis & Parr 2003): LSTD-Q with a small ridge term.

Samples (s, a, r, s', done) are kept (up to `capacity`, newest kept); `iterate()` runs one LSTD-Q
evaluation of the current greedy policy over all of them, which is one policy-iteration step.
Features come from a basis with `k` and `phi(states, actions) -> (n, k)` (dense or scipy sparse).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


class Basis(Protocol):
    """What LSPI needs of a linear architecture: `k` features per (state, action) pair over
    `n_actions` actions, and `phi(states, actions)` -> feature rows [n, k] (dense or scipy sparse)."""

    @property
    def k(self) -> int:
        """Number of features per (state, action) pair."""
        ...

    @property
    def n_actions(self) -> int:
        """Number of discrete actions."""
        ...

    def phi(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray | sp.csr_matrix:
        """Feature rows [n, k] of the pairs (states[i], actions[i])."""
        ...


@dataclass(frozen=True)
class TabularBasis:
    """One-hot over (state, action): the tabular case as a linear architecture."""

    n_states: int
    n_actions: int

    @property
    def k(self) -> int:
        """Number of features: n_states * n_actions."""
        return self.n_states * self.n_actions

    def phi(self, states: np.ndarray, actions: np.ndarray) -> sp.csr_matrix:
        """Sparse one-hot rows [n, k] for the (state, action) pairs."""
        states = np.asarray(states, dtype=np.int64).reshape(-1)
        actions = np.asarray(actions, dtype=np.int64).reshape(-1)
        if states.size and (states.min() < 0 or states.max() >= self.n_states):
            raise ValueError(f"state ids must be in 0..{self.n_states - 1}")
        cols = states * self.n_actions + actions
        n = cols.size
        return sp.csr_matrix((np.ones(n), (np.arange(n), cols)), shape=(n, self.k))


@dataclass(frozen=True)
class RBFBasis:
    """Gaussian radial basis functions of a scalar state (plus a constant), one block per action."""

    centres: tuple[float, ...]
    width: float
    n_actions: int

    @property
    def k(self) -> int:
        """Number of features: (len(centres) + 1) * n_actions."""
        return (len(self.centres) + 1) * self.n_actions

    def phi(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Dense rows [n, k]: the RBF block (and constant) of each state in its action's columns."""
        x = np.asarray(states, dtype=np.float64).reshape(-1, 1)
        a = np.asarray(actions, dtype=np.int64).reshape(-1)
        f = np.hstack([np.ones((x.shape[0], 1)), np.exp(-0.5 * ((x - np.asarray(self.centres)) / self.width) ** 2)])
        out = np.zeros((x.shape[0], self.k))
        m = f.shape[1]
        for j in range(self.n_actions):
            rows = a == j
            out[rows, j * m : (j + 1) * m] = f[rows]
        return out


class LSPI:
    """Least-squares policy iteration over a linear basis (see the module docstring).

    Parameters
    ----------
    basis : Basis
        The features, e.g. `TabularBasis` (integer states) or `RBFBasis` (scalar states).
    gamma : float, default 0.9
        Discount, in [0, 1).
    ridge : float, default 1e-3
        Ridge term added to the LSTD-Q matrix (keeps it invertible; perturbs exact ties slightly).
    capacity : int, default 50_000
        Samples kept; the oldest are dropped beyond it.
    tie_tolerance : float, default 0.05
        Relative tolerance within which actions count as tied in `greedy`.

    Examples
    --------
    Learn from samples, iterate, act greedily::

        lspi = LSPI(TabularBasis(n_states=25, n_actions=4), gamma=0.9)
        lspi.learn_one(s, a, r, s_next, done)  # for each observed step
        lspi.iterate()  # one policy-iteration step over all stored samples
        a = lspi.greedy(s)
    """

    #: LSTD-Q systems with more features than this, when sparse (tables), are solved sparsely
    SPARSE_SOLVE_ABOVE = 2000

    def __init__(
        self,
        basis: Basis,
        gamma: float = 0.9,
        ridge: float = 1e-3,
        capacity: int = 50_000,
        tie_tolerance: float = 0.05,
    ) -> None:
        if not 0.0 <= gamma < 1.0:
            raise ValueError("gamma must be in [0, 1)")
        if ridge < 0:
            raise ValueError("ridge must be >= 0")
        if capacity < 1:
            raise ValueError("capacity must be >= 1")
        self.basis = basis
        self.gamma = gamma
        self.ridge = ridge
        self.capacity = capacity
        self.tie_tolerance = tie_tolerance
        self.reset()

    def reset(self) -> None:
        """Forget every sample and set the weights to zero."""
        self._s: list[float] = []
        self._a: list[int] = []
        self._r: list[float] = []
        self._s2: list[float] = []
        self._done: list[bool] = []
        self.w = np.zeros(self.basis.k)
        self.iterations = 0

    def state(self) -> dict[str, Any]:
        """The stored samples, weights and iteration count (the basis and settings are configuration)."""
        return {
            "s": np.array(self._s),
            "a": np.array(self._a, dtype=np.int64),
            "r": np.array(self._r, dtype=np.float64),
            "s_next": np.array(self._s2),
            "done": np.array(self._done, dtype=bool),
            "w": self.w.copy(),
            "iterations": self.iterations,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of an LSPI with the same basis."""
        w = np.array(state["w"], dtype=np.float64)
        if w.shape != (self.basis.k,):
            raise ValueError(f"LSPI weights have shape {w.shape}, the basis needs ({self.basis.k},)")
        cols = [np.asarray(state[k]) for k in ("s", "a", "r", "s_next", "done")]
        if len({c.size for c in cols}) != 1 or cols[0].size > self.capacity:
            raise ValueError("LSPI sample columns differ in length or exceed the capacity")
        # back to the Python lists learn_one appends to (ints stay ints, floats floats)
        self._s, self._a, self._r, self._s2, self._done = (c.reshape(-1).tolist() for c in cols)
        self.w = w
        self.iterations = int(state["iterations"])

    def samples(self) -> dict[str, Any]:
        """The stored samples and weights, as list copies (cheap: for a background job's snapshot;
        `restore` takes it like a `state()`)."""
        return {
            "s": list(self._s),
            "a": list(self._a),
            "r": list(self._r),
            "s_next": list(self._s2),
            "done": list(self._done),
            "w": self.w.copy(),
            "iterations": self.iterations,
        }

    @property
    def n_samples(self) -> int:
        """Number of samples stored."""
        return len(self._s)

    def learn_one(self, s: float, a: int, r: float, s_next: float, done: bool) -> None:
        """Store one sample (s, a, r, s', done); learning happens in `iterate`.

        Parameters
        ----------
        s : float
            State as the basis takes it (a state id for `TabularBasis`, a scalar for `RBFBasis`).
        a : int
            Action taken.
        r : float
            Reward received.
        s_next : float
            The next state.
        done : bool
            Whether `s_next` is terminal (its value then counts as 0).
        """
        self._s.append(s)
        self._a.append(int(a))
        self._r.append(float(r))
        self._s2.append(s_next)
        self._done.append(bool(done))
        if len(self._s) > self.capacity:
            for buf in (self._s, self._a, self._r, self._s2, self._done):
                del buf[0]

    def q(self, s: float) -> np.ndarray:
        """Q(s, a) for every action a: [n_actions]."""
        n = self.basis.n_actions
        return np.asarray(self.basis.phi(np.full(n, s), np.arange(n)) @ self.w).reshape(-1)

    def greedy(self, s: float, prefer: int | None = None) -> int:
        """The greedy action argmax_a Q(s, a), with consistent tie-breaking.

        Among near-ties (within `tie_tolerance` of the best, relative), keep `prefer` (e.g. the
        previous action) if it is one of them, else the lowest index. Consistent tie-breaking gives
        consistent traces, which the embedding needs. The tolerance is relative because with goal
        rewards the gap between an optimal and a detour action is the fixed fraction 1 - gamma^2 of
        the value, while the ridge term perturbs exact ties slightly.

        Parameters
        ----------
        s : float
            State as the basis takes it.
        prefer : int, optional
            Action to keep when it is among the near-ties.

        Returns
        -------
        int
            The chosen action.
        """
        return self.choose(self.q(s), prefer)

    def choose(self, q: np.ndarray, prefer: int | None = None) -> int:
        """The greedy action for action values `q`, near-ties broken as `greedy` does (for callers
        that compute Q themselves, e.g. from features of an observation never stored)."""
        ties = np.flatnonzero(self._tied(np.asarray(q, dtype=np.float64)[None, :])[0])
        if prefer is not None and prefer in ties:
            return int(prefer)
        return int(ties[0])

    def _greedy_many(self, states: np.ndarray) -> np.ndarray:
        n = self.basis.n_actions
        Q = np.stack(
            [np.asarray(self.basis.phi(states, np.full(states.size, a)) @ self.w).reshape(-1) for a in range(n)], axis=1
        )
        return self._tied(Q).argmax(axis=1)

    def _tied(self, Q: np.ndarray) -> np.ndarray:
        best = Q.max(axis=1, keepdims=True)
        return Q >= best - self.tie_tolerance * np.abs(best) - 1e-12

    def iterate(self) -> float:
        """One LSTD-Q policy evaluation of the current greedy policy; returns ||w_new - w_old||."""
        if not self._s:
            return 0.0
        S, A, R = np.array(self._s), np.array(self._a), np.array(self._r)
        S2, done = np.array(self._s2), np.array(self._done)
        A2 = self._greedy_many(S2)
        Phi = self.basis.phi(S, A)
        Phi2 = self.basis.phi(S2, A2)
        # dense features (RBFBasis) are an ndarray, sparse ones (TabularBasis) scipy sparse: mask terminal rows
        Phi2 = Phi2 * (~done)[:, None] if isinstance(Phi2, np.ndarray) else Phi2.multiply((~done)[:, None]).tocsr()
        Amat = Phi.T @ (Phi - self.gamma * Phi2)
        b = np.asarray(Phi.T @ R).reshape(-1)
        if sp.issparse(Amat) and Amat.shape[0] > self.SPARSE_SOLVE_ABOVE:
            # a large table (thousands of state-action pairs): a dense k x k solve would take GBs
            w = spla.spsolve((Amat + self.ridge * sp.identity(Amat.shape[0])).tocsc(), b)
        else:
            Amat = Amat.toarray() if sp.issparse(Amat) else np.asarray(Amat)
            Amat[np.diag_indices_from(Amat)] += self.ridge
            w = np.linalg.solve(Amat, b)
        change = float(np.linalg.norm(w - self.w))
        self.w = w
        self.iterations += 1
        return change
