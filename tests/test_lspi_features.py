"""The LSPI feature basis over stored observations (agent/learners/lspi_features.py), with and
without the last action in the state."""

from __future__ import annotations

import numpy as np
import pytest

from sensorimotor.agent.learners.lspi_features import RBFFeatures


def _fitted(hist: np.ndarray | None, n_hist: int) -> RBFFeatures:
    rng = np.random.default_rng(0)
    store = rng.standard_normal((12, 5)).astype(np.float32)
    rbf = RBFFeatures(store, 3, 4, hist, n_hist)
    rbf.fit(store.astype(np.float64), components=3, n_centres=4, width=1.0)
    return rbf


@pytest.mark.parametrize("remember", [False, True])
def test_q_of_an_observation_equals_its_sample_features_times_the_weights(remember):
    hist = np.arange(12, dtype=np.int16) % 4 if remember else None
    rbf = _fitted(hist, 4 if remember else 1)
    assert rbf.k == 5 * 3 * (4 if remember else 1)
    w = np.random.default_rng(1).standard_normal(rbf.k)
    for row in range(12):
        h = int(hist[row]) if hist is not None else 0
        q = rbf.q(w, rbf.store[row].astype(np.float64), h)
        by_phi = [float((rbf.phi(np.array([row]), np.array([a])) @ w)[0]) for a in range(3)]
        assert q == pytest.approx(by_phi, abs=1e-12)
    if remember:  # each (action, last action) pair has its own block: other blocks' weights do not count
        phi = rbf.phi(np.array([0, 1]), np.array([2, 2])).toarray()
        assert np.flatnonzero(phi[0]).min() // 5 == 2 * 4 + 0 and np.flatnonzero(phi[1]).min() // 5 == 2 * 4 + 1


def test_history_values_and_their_count_go_together():
    store = np.zeros((4, 2), dtype=np.float32)
    with pytest.raises(ValueError, match="hist and n_hist"):
        RBFFeatures(store, 2, 3, None, 3)
    with pytest.raises(ValueError, match="hist and n_hist"):
        RBFFeatures(store, 2, 3, np.zeros(4, dtype=np.int16), 1)
