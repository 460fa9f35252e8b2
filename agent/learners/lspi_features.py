"""LSPI over observations that are neither state ids nor symbols (ch. 6: PCA + RBF): the feature
basis over stored observations, and the policy-iteration job the generic program runs off the act
path (a pure function of a snapshot: `agent.programs.background`)."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from sensorimotor.agent.learners.lspi import LSPI, TabularBasis


class RBFFeatures:
    """LSPI basis over observation ids: id -> stored (projected) observation -> PCA -> RBFs, one
    block of `centres + 1` features per action. Refitted between policy iterations.

    With `hist` (one small integer per stored row, 0 .. `n_hist` - 1: the action sent before the
    observation, plus one) the state is the observation *and* that action: each action's block is
    `n_hist` blocks, one per value, so a body whose actions act a step late is a function of the
    state again (`agent.programs.generic_relearn`)."""

    def __init__(
        self, store: np.ndarray, n_actions: int, n_centres: int, hist: np.ndarray | None = None, n_hist: int = 1
    ) -> None:
        if (hist is None) != (n_hist == 1) or n_hist < 1:
            raise ValueError("RBFFeatures: hist and n_hist > 1 go together")
        self.store = store
        self.hist = hist
        self.n_hist = n_hist
        self.n_actions = n_actions
        self.m = n_centres + 1
        self.mean = np.zeros(store.shape[1])
        self.axes = np.zeros((store.shape[1], 0))
        self.scale = np.ones(0)
        self.centres = np.zeros((0, 0))
        self.width = 1.0
        self._cache = np.zeros((store.shape[0], self.m))  # features of stored rows under this fit
        self._cached = np.zeros(store.shape[0], dtype=bool)

    @property
    def k(self) -> int:
        return self.m * self.n_actions * self.n_hist

    def q(self, w: np.ndarray, x: np.ndarray, h: int = 0) -> np.ndarray:
        """The value of each action at the (projected) observation `x` after history value `h`."""
        f = self.features(x)[0]
        return np.asarray(w).reshape(self.n_actions, self.n_hist, self.m)[:, h, :] @ f

    def forget(self, rows: np.ndarray | int | slice) -> None:
        """Stored rows were overwritten: their cached features are stale."""
        self._cached[rows] = False

    def fit(self, X: np.ndarray, components: int, n_centres: int, width: float) -> None:
        """PCA of the sample `X` (rows), then RBF centres by farthest-point sampling in its scores,
        starting from the point nearest the mean (deterministic given the sample)."""
        self._cached[:] = False
        self.mean = X.mean(axis=0)
        Xc = X - self.mean
        _, s, vt = np.linalg.svd(Xc, full_matrices=False)
        c = max(1, min(components, int((s > 1e-9 * max(s[0], 1e-300)).sum()) if s.size else 1))
        self.axes = np.ascontiguousarray(vt[:c].T)  # the layout a restored copy has: same rounding
        Z = Xc @ self.axes
        self.scale = Z.std(axis=0) + 1e-12
        Z = Z / self.scale
        n = min(n_centres, Z.shape[0])
        chosen = [int(np.linalg.norm(Z, axis=1).argmin())]
        dist = np.linalg.norm(Z - Z[chosen[0]], axis=1)
        for _ in range(1, n):
            i = int(dist.argmax())
            chosen.append(i)
            dist = np.minimum(dist, np.linalg.norm(Z - Z[i], axis=1))
        centres = Z[chosen]
        if centres.shape[0] < n_centres:  # fewer distinct points than centres: repeat (features stay finite)
            centres = np.resize(centres, (n_centres, centres.shape[1]))
        self.centres = centres
        d = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=2)
        d[np.diag_indices_from(d)] = np.inf
        nearest = d.min(axis=1)
        spacing = float(np.median(nearest[np.isfinite(nearest) & (nearest > 0)])) if np.any(nearest > 0) else 1.0
        self.width = width * (spacing if np.isfinite(spacing) and spacing > 0 else 1.0)

    def features(self, X: np.ndarray) -> np.ndarray:
        """RBF features (with a constant) of raw (projected) observations: (n, m). Each row is
        computed on its own (einsum and broadcasting, not BLAS, whose rounding depends on the batch),
        so a row's features do not depend on which rows it was computed with: a run restored from a
        checkpoint or replayed offline computes exactly the same numbers."""
        Z = np.einsum("nd,dc->nc", np.atleast_2d(X) - self.mean, self.axes) / self.scale
        d2 = ((Z[:, None, :] - self.centres[None, :, :]) ** 2).sum(axis=2)
        return np.hstack([np.ones((Z.shape[0], 1)), np.exp(-0.5 * d2 / self.width**2)])

    def phi(self, ids: np.ndarray, actions: np.ndarray) -> sp.csr_matrix:
        rows = np.asarray(ids, dtype=np.int64).reshape(-1) % self.store.shape[0]
        a = np.asarray(actions, dtype=np.int64).reshape(-1)
        todo = np.unique(rows[~self._cached[rows]])
        if todo.size:
            self._cache[todo] = self.features(self.store[todo].astype(np.float64))
            self._cached[todo] = True
        f = self._cache[rows]
        # one block of m features per row, at the column block of its action (and history value):
        # sparse, 1/(n_actions n_hist) dense
        block = a if self.hist is None else a * self.n_hist + self.hist[rows].astype(np.int64)
        cols = (block[:, None] * self.m + np.arange(self.m)[None, :]).ravel()
        return sp.csr_matrix((f.ravel(), cols, np.arange(0, f.size + 1, self.m)), shape=(rows.size, self.k))


def basis_state(b: RBFFeatures) -> dict[str, Any]:
    return {
        "mean": b.mean.copy(),
        "axes": b.axes.copy(),
        "scale": b.scale.copy(),
        "centres": b.centres.copy(),
        "width": b.width,
    }


def set_basis(b: RBFFeatures, s: dict[str, Any]) -> None:
    b.mean, b.axes, b.scale = (np.array(s[k], dtype=np.float64) for k in ("mean", "axes", "scale"))
    b.centres, b.width = np.array(s["centres"], dtype=np.float64), float(s["width"])
    b.forget(slice(None))


def iterate_job(
    n_states: int,
    n_actions: int,
    gamma: float,
    ridge: float,
    capacity: int,
    iterations: int,
    samples: dict[str, Any],
    store: np.ndarray | None,
    basis: dict[str, Any] | None,
    refit: np.ndarray | None,
    fit: dict[str, Any],
    tie_tolerance: float = 0.05,
    hist: np.ndarray | None = None,
) -> dict[str, Any]:
    """Feature refit (when `refit` holds the reservoir sample) and up to `iterations` LSPI
    iterations over a snapshot of the samples: the new basis (if refitted), weights, iterations
    done and the last change. Tabular when `store` is None; `hist`: the stored rows' history values
    (`RBFFeatures`, `fit["n_hist"]` of them). A pure function, run off the act path."""
    if store is None:
        lspi = LSPI(
            TabularBasis(n_states, n_actions), gamma=gamma, ridge=ridge, capacity=capacity, tie_tolerance=tie_tolerance
        )
    else:
        h = None if hist is None else np.asarray(hist)
        rbf = RBFFeatures(np.asarray(store), n_actions, int(fit["centres"]), h, int(fit.get("n_hist", 1)))
        if refit is not None:
            rbf.fit(
                np.asarray(refit, dtype=np.float64), int(fit["components"]), int(fit["centres"]), float(fit["width"])
            )
        else:
            assert basis is not None
            set_basis(rbf, basis)
        lspi = LSPI(rbf, gamma=gamma, ridge=ridge, capacity=capacity, tie_tolerance=tie_tolerance)
    lspi.restore(samples)
    change, done = 0.0, 0
    for _ in range(iterations):  # policy iteration until the weights settle
        change = lspi.iterate()
        done += 1
        if change <= 1e-3 * (float(np.linalg.norm(lspi.w)) + 1e-12):
            break
    return {
        "w": lspi.w,
        "iterations": done,
        "change": change,
        "basis": None if store is None or refit is None else basis_state(rbf),
    }


__all__ = ["RBFFeatures", "basis_state", "iterate_job", "set_basis"]
