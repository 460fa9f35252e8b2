import numpy as np
import pytest
from scipy.spatial import procrustes as scipy_procrustes
from scipy.spatial.distance import cdist

from sensorimotor.agent.embedding import classical_mds, procrustes, procrustes_error, trace_distances


def naive_padded(traces, pad="append"):
    n = len(traces)
    D = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            a, b = np.asarray(traces[i], float), np.asarray(traces[j], float)
            L = max(len(a), len(b))
            za, zb = np.zeros((L, a.shape[1])), np.zeros((L, b.shape[1]))
            if pad == "append":
                za[: len(a)], zb[: len(b)] = a, b
            else:
                za[L - len(a) :], zb[L - len(b) :] = a, b
            D[i, j] = sum(np.linalg.norm(za[t] - zb[t]) for t in range(L))
    return D


def naive_edit(a, b, sub=1):
    D = np.zeros((len(a) + 1, len(b) + 1))
    D[:, 0] = np.arange(len(a) + 1)
    D[0, :] = np.arange(len(b) + 1)
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            D[i, j] = min(D[i - 1, j] + 1, D[i, j - 1] + 1, D[i - 1, j - 1] + (0 if a[i - 1] == b[j - 1] else sub))
    return D[-1, -1]


@pytest.mark.parametrize("pad", ["append", "prepend"])
def test_continuous_trace_distances_match_naive(pad):
    rng = np.random.default_rng(1)
    traces = [rng.normal(size=(rng.integers(0, 7), 2)) for _ in range(12)]
    np.testing.assert_allclose(trace_distances(traces, "continuous", pad=pad), naive_padded(traces, pad), atol=1e-12)


def test_append_and_prepend_differ_for_unequal_lengths():
    traces = [np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([[0.0, 1.0]])]
    assert trace_distances(traces, pad="append")[0, 1] != trace_distances(traces, pad="prepend")[0, 1]


@pytest.mark.parametrize("sub", [1, 2])
def test_edit_distances_match_naive(sub):
    rng = np.random.default_rng(2)
    traces = [list(rng.integers(0, 4, size=rng.integers(0, 9))) for _ in range(15)]
    D = trace_distances(traces, "edit", substitution_cost=sub)
    for i in range(15):
        for j in range(15):
            assert D[i, j] == naive_edit(traces[i], traces[j], sub)


def test_ballistic_traces_give_euclidean_distances():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(20, 2))
    np.testing.assert_allclose(trace_distances([p[None, :] for p in pts]), cdist(pts, pts), atol=1e-12)


@pytest.mark.parametrize("method", ["full", "topk"])
def test_mds_recovers_euclidean_points_up_to_rotation(method):
    rng = np.random.default_rng(4)
    X = rng.normal(size=(60, 3))
    res = classical_mds(cdist(X, X), 3, method=method)
    assert procrustes_error(X, res.coordinates) < 1e-20
    # pairwise distances are preserved exactly (rotation + translation only, no scaling)
    np.testing.assert_allclose(cdist(res.coordinates, res.coordinates), cdist(X, X), atol=1e-9)
    assert res.eigenvalues[0] >= res.eigenvalues[1] >= res.eigenvalues[2] > 0


def test_mds_spectrum_shows_dimension_and_negative_eigenvalues_of_non_euclidean_input():
    rng = np.random.default_rng(5)
    X = rng.normal(size=(40, 2))
    w = classical_mds(cdist(X, X), 2, method="full").eigenvalues
    assert w[2] < 1e-9 * w[0]  # exactly 2-D
    L1 = cdist(X, X, "cityblock")
    assert classical_mds(L1, 2, method="full").eigenvalues.min() < -1e-6


def test_mds_rejects_bad_input():
    with pytest.raises(ValueError, match="square"):
        classical_mds(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="NaN"):
        classical_mds(np.full((3, 3), np.nan))


def test_mds_is_deterministic_in_sign():
    rng = np.random.default_rng(6)
    X = rng.normal(size=(30, 2))
    a = classical_mds(cdist(X, X), 2).coordinates
    b = classical_mds(cdist(X, X), 2).coordinates
    assert a.tobytes() == b.tobytes()


def test_procrustes_equals_scipy():
    rng = np.random.default_rng(7)
    for _ in range(5):
        A, B = rng.normal(size=(25, 2)), rng.normal(size=(25, 2))
        assert procrustes_error(A, B) == pytest.approx(scipy_procrustes(A, B)[2], rel=1e-10)
    A = rng.normal(size=(25, 2))
    R = np.array([[0.0, -1.0], [1.0, 0.0]])
    assert procrustes_error(A, 3.0 * A @ R + 5.0) < 1e-25
    assert procrustes(A, A[:, ::-1]).disparity < 1e-25  # reflections allowed, as in scipy


def test_procrustes_pads_lower_dimensional_embedding():
    x = np.linspace(0, 1, 10)
    assert procrustes_error(np.c_[x, np.zeros(10)], x) < 1e-25
    with pytest.raises(ValueError, match="identical"):
        procrustes_error(np.zeros((4, 2)), np.ones((4, 2)))
