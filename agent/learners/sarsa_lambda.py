"""Sarsa(lambda) with tile coding (CMAC), as ch. 8 uses on (position, velocity).

Tile coding: `n_tilings` offset grids over the box `low..high`, `tiles` cells per dimension; a
state activates one tile per tiling. Q(s, a) = sum of the active tiles' weights for a. Replacing
eligibility traces; epsilon-greedy; step size alpha / n_tilings per tile.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from sensorimotor.agent.snapshot import rng_state, set_rng_state


class TileCoder:
    """Tile coding (CMAC) of a box: `n_tilings` offset grids, `tiles` cells per dimension.

    Parameters
    ----------
    low, high : array-like
        Bounds of the state box (states outside are clipped to it).
    tiles : int, default 10
        Cells per dimension and tiling.
    n_tilings : int, default 8
        Number of offset tilings (one active tile each).
    memory : int or None, default None
        When the tilings hold more tiles than this, tiles are hashed into `memory` weights
        (Sutton's hashed tile coding: only the tiles a learner visits matter, so a 12-dimensional
        box needs no 9^12 table; a collision shares one weight between two far-apart tiles).
    """

    def __init__(
        self, low: ArrayLike, high: ArrayLike, tiles: int = 10, n_tilings: int = 8, memory: int | None = None
    ) -> None:
        self.low, self.high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
        if self.low.shape != self.high.shape or not (self.high > self.low).all():
            raise ValueError("low/high must have the same shape and high > low")
        if tiles < 1 or n_tilings < 1:
            raise ValueError("tiles and n_tilings must be >= 1")
        self.tiles, self.n_tilings = tiles, n_tilings
        self.dims = self.low.size
        self.per_tiling = (tiles + 1) ** self.dims
        self.size = self.per_tiling * n_tilings
        self.hashed = memory is not None and self.size > memory
        if self.hashed:
            assert memory is not None
            self.size = int(memory)
            # fixed odd multipliers (a multiplicative hash of the cell coordinates), the same on every run
            self._mult = np.random.default_rng([self.dims, 8]).integers(1, 2**31, size=self.dims) * 2 + 1
        # tiling j is offset by j/n_tilings of a tile, with a different stride per dimension
        self._offsets = (np.arange(n_tilings)[:, None] * (1 + 2 * np.arange(self.dims))[None, :] / n_tilings) % 1.0
        self._strides = (tiles + 1) ** np.arange(self.dims)

    def active(self, state: np.ndarray) -> np.ndarray:
        """Indices of the `n_tilings` active tiles."""
        s = (np.clip(np.asarray(state, dtype=np.float64), self.low, self.high) - self.low) / (self.high - self.low)
        cells = np.floor(s[None, :] * self.tiles + self._offsets).astype(np.int64)
        cells = np.minimum(cells, self.tiles)
        if self.hashed:
            h = (cells * self._mult).sum(axis=1) + np.arange(self.n_tilings) * 0x9E3779B1
            return (h ^ (h >> 17)) % self.size
        return cells @ self._strides + np.arange(self.n_tilings) * self.per_tiling


class SarsaLambda:
    """Sarsa(lambda) with linear function approximation over a `TileCoder`, replacing traces.

    Parameters
    ----------
    coder : TileCoder
        The state features.
    n_actions : int
        Number of discrete actions.
    alpha : float, default 0.3
        Step size (divided among the tilings), in (0, 1].
    gamma : float, default 0.99
        Discount.
    lam : float, default 0.9
        Trace decay lambda.
    epsilon : float, default 0.0
        Probability of a random action in `act`.
    seed : int, default 0
        Seed of the learner's generator.
    trace_cutoff : float, default 0.0
        Eligibility traces below this are dropped, and only the live ones are updated (0: every
        weight's trace is kept and decayed, the textbook form). With hashed tiles the weight table
        is large (actions x memory) and decaying all of it every step costs more than the rest.
    """

    def __init__(
        self,
        coder: TileCoder,
        n_actions: int,
        alpha: float = 0.3,
        gamma: float = 0.99,
        lam: float = 0.9,
        epsilon: float = 0.0,
        seed: int = 0,
        trace_cutoff: float = 0.0,
    ) -> None:
        if not 0 < alpha <= 1 or not 0 <= gamma <= 1 or not 0 <= lam <= 1 or not 0 <= epsilon <= 1:
            raise ValueError("need 0 < alpha <= 1 and gamma, lambda, epsilon in [0, 1]")
        self.coder, self.n_actions = coder, n_actions
        self.alpha, self.gamma, self.lam, self.epsilon = alpha, gamma, lam, epsilon
        self.seed = seed
        self.trace_cutoff = trace_cutoff
        self.reset()

    def reset(self) -> None:
        """Zero weights and traces, and reseed the generator."""
        self.rng = np.random.default_rng(self.seed)
        self.w = np.zeros((self.n_actions, self.coder.size))
        self.z = np.zeros_like(self.w)
        self._live = np.zeros(0, dtype=np.int64)  # flat indices of the traces above the cutoff

    def state(self) -> dict[str, Any]:
        """Weights, eligibility traces and the generator (the tile coder and settings are configuration)."""
        return {"seed": self.seed, "rng": rng_state(self.rng), "w": self.w.copy(), "z": self.z.copy()}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a learner with the same tile coder and actions."""
        w, z = np.array(state["w"], dtype=np.float64), np.array(state["z"], dtype=np.float64)
        if w.shape != self.w.shape or z.shape != self.w.shape:
            raise ValueError(f"Sarsa weights have shape {w.shape}, this learner needs {self.w.shape}")
        self.seed = int(state["seed"])
        set_rng_state(self.rng, state["rng"])
        self.w, self.z = w, z
        self._live = np.flatnonzero(z.reshape(-1)) if self.trace_cutoff > 0 else np.zeros(0, dtype=np.int64)

    def q(self, state: np.ndarray) -> np.ndarray:
        """Q(state, a) for every action: [n_actions]."""
        return self.w[:, self.coder.active(state)].sum(axis=1)

    def act(self, state: np.ndarray) -> int:
        """Epsilon-greedy action for `state` (ties broken at random): for learning.

        Parameters
        ----------
        state : np.ndarray
            The continuous state (e.g. position, velocity).

        Returns
        -------
        int
            The action.
        """
        if self.rng.random() < self.epsilon:
            return int(self.rng.integers(self.n_actions))
        q = self.q(state)
        best = np.flatnonzero(q == q.max())
        return int(best[self.rng.integers(best.size)])

    def greedy(self, state: np.ndarray) -> int:
        """The best action, ties to the lowest index: deterministic, for evaluation.

        Parameters
        ----------
        state : np.ndarray
            The continuous state.

        Returns
        -------
        int
            The action.
        """
        q = self.q(state)
        return int(np.flatnonzero(q == q.max())[0])

    def begin_episode(self) -> None:
        """Clear the eligibility traces at the start of an episode."""
        if self.trace_cutoff > 0:
            self.z.reshape(-1)[self._live] = 0.0
            self._live = np.zeros(0, dtype=np.int64)
        else:
            self.z[:] = 0.0

    def learn_one(self, s: np.ndarray, a: int, r: float, s2: np.ndarray, a2: int | None) -> None:
        """One Sarsa(lambda) update for the step (s, a, r, s2, a2).

        Parameters
        ----------
        s : np.ndarray
            State the action was taken in.
        a : int
            Action taken.
        r : float
            Reward received.
        s2 : np.ndarray
            The next state.
        a2 : int or None
            Action chosen in `s2`; None when `s2` is terminal (its value counts as 0).
        """
        tiles = self.coder.active(s)
        target = r + (0.0 if a2 is None else self.gamma * self.q(s2)[a2])
        delta = target - self.w[a, tiles].sum()
        if self.trace_cutoff > 0:
            self._learn_sparse(tiles, a, delta)
            return
        self.z *= self.gamma * self.lam
        self.z[:, tiles] = 0.0
        self.z[a, tiles] = 1.0  # replacing traces
        self.w += (self.alpha / self.coder.n_tilings) * delta * self.z

    def _learn_sparse(self, tiles: np.ndarray, a: int, delta: float) -> None:
        """The same update on the live traces only (see `trace_cutoff`)."""
        z, w, size = self.z.reshape(-1), self.w.reshape(-1), self.coder.size
        live = self._live
        z[live] *= self.gamma * self.lam
        touched = (np.arange(self.n_actions)[:, None] * size + tiles[None, :]).reshape(-1)
        z[touched] = 0.0  # replacing traces: every action's trace of the active tiles is cleared
        mine = a * size + tiles
        z[mine] = 1.0
        live = np.union1d(live[z[live] >= self.trace_cutoff], mine)
        w[live] += (self.alpha / self.coder.n_tilings) * delta * z[live]
        self._live = live
