"""Motor coordinates of a high-dimensional observation: the map from what a sensor sees (a camera
frame) to a point whose moves are the moves the agent commanded.

Why: a planner over a grid needs a low-dimensional state, and the principal components of camera
frames are a poor one (their axes follow pixel variance, not the body). A body whose commands add up
(a hand sent by displacements) has a better one, found from its own experience: coordinates `z`
such that `z(after) - z(before)` is the action that was sent. The map is linear in quadratic
features of the frames' whitened principal components, fitted by ridge regression on the
transitions of random moves, so it needs nothing but frames and the actions sent (no truth).
The coordinates are the agent's own, in units of its commands; the planner then learns how each
action moves them, as it does for a state vector, so an imperfect map (a bend, a scale per axis)
costs plan quality, not correctness.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse.linalg import svds


@dataclass(frozen=True)
class MotorMap:
    """A fitted map: frames (rows of `mean`'s length) to motor coordinates (columns of `weights`)."""

    mean: np.ndarray  # [d] the frames' mean
    basis: np.ndarray  # [d, k] principal axes, scaled so the components have unit variance
    weights: np.ndarray  # [k + k(k+1)/2, m] quadratic features -> motor coordinates

    def features(self, X: np.ndarray) -> np.ndarray:
        """The components of frames `X` [n, d] and their pairwise products [n, k + k(k+1)/2]."""
        F = (np.atleast_2d(X) - self.mean) @ self.basis
        i, j = np.triu_indices(F.shape[1])
        return np.hstack([F, F[:, i] * F[:, j]])

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Motor coordinates of frames `X` [n, d] (or one frame [d]: then [m])."""
        z = self.features(X) @ self.weights
        return z[0] if np.ndim(X) == 1 else z

    def state(self) -> dict[str, Any]:
        return {"mean": self.mean.copy(), "basis": self.basis.copy(), "weights": self.weights.copy()}

    @classmethod
    def from_state(cls, s: dict[str, Any]) -> MotorMap:
        return cls(*(np.asarray(s[k], dtype=np.float64) for k in ("mean", "basis", "weights")))


def fit_motor_map(
    before: np.ndarray,
    actions: np.ndarray,
    after: np.ndarray,
    components: int = 32,
    ridge: float = 1e-2,
    seed: int = 0,
) -> MotorMap:
    """Fit coordinates whose differences over each transition are the action sent.

    Parameters
    ----------
    before, after : np.ndarray
        The frames [n, d] before and after each transition (flattened, scaled).
    actions : np.ndarray
        The action sent in each transition [n, m].
    components : int
        Principal components of the frames kept (their quadratic features number k + k(k+1)/2).
    ridge : float
        Ridge penalty, relative to the mean diagonal of the features' Gram matrix.
    seed : int
        Seeds the start vector of the partial SVD (the fit is deterministic given it).

    Returns
    -------
    MotorMap
    """
    before, after = np.asarray(before, dtype=np.float64), np.asarray(after, dtype=np.float64)
    actions = np.asarray(actions, dtype=np.float64)
    n, d = before.shape
    if after.shape != before.shape or actions.ndim != 2 or actions.shape[0] != n:
        raise ValueError(f"transitions disagree: before {before.shape}, actions {actions.shape}, after {after.shape}")
    X = np.vstack([before, after])
    k = int(min(components, d - 1, X.shape[0] - 1))
    if k < 1:
        raise ValueError(f"too few transitions ({n}) or values ({d}) to fit motor coordinates")
    mean = X.mean(axis=0)
    v0 = np.random.default_rng(seed).standard_normal(min(X.shape))
    _, sv, vt = svds(X - mean, k=k, v0=v0, solver="arpack")
    order = np.argsort(sv)[::-1]
    sv, vt = sv[order], vt[order]
    keep = sv > 1e-9 * max(sv[0], 1e-300)
    basis = np.ascontiguousarray(vt[keep].T / sv[keep] * np.sqrt(X.shape[0]))  # as a restored copy is
    m = MotorMap(mean, basis, np.zeros((0, actions.shape[1])))
    D = m.features(after) - m.features(before)
    G = D.T @ D
    lam = ridge * max(float(np.trace(G)) / G.shape[0], 1e-12)
    W = np.linalg.solve(G + lam * np.eye(G.shape[0]), D.T @ actions)
    return MotorMap(mean, basis, W)


__all__ = ["MotorMap", "fit_motor_map"]
