"""The fast paths equal the references; landmark and out-of-sample embedding are exact where
they must be."""

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from sensorimotor.agent.embedding import (
    PreparedTraces,
    classical_mds,
    landmark_mds,
    landmark_trace_embedding,
    procrustes_error,
    trace_cross_distances,
    trace_distances,
    update_trace_distances,
)
from sensorimotor.agent.embedding import trace_kernels as K
from tests.test_embedding_math import naive_edit, naive_padded


def traces(n=40, seed=0, d=2, maxlen=9):
    rng = np.random.default_rng(seed)
    return [rng.normal(size=(rng.integers(0, maxlen), d)) for _ in range(n)]


@pytest.mark.parametrize("pad", ["append", "prepend"])
def test_compiled_pairs_equal_naive_and_numpy(pad):
    tr = traces()
    D = trace_distances(tr, pad=pad)
    np.testing.assert_allclose(D, naive_padded(tr, pad), atol=1e-12)
    from sensorimotor.agent.embedding.trace_distances import pad_traces

    ref = np.empty_like(D)
    K.padded_sum_pairs_numpy(pad_traces(tr, pad), ref)
    np.testing.assert_allclose(D, ref, atol=1e-12)
    assert np.array_equal(D, D.T) and not np.diag(D).any()


@pytest.mark.parametrize("n", [1, 2, 3, 7, 8])
def test_pair_kernel_covers_every_pair_for_odd_and_even_n(n):
    tr = traces(n, seed=n)
    np.testing.assert_allclose(trace_distances(tr), naive_padded(tr), atol=1e-12)


def test_float32_matrix():
    tr = traces()
    D32 = trace_distances(tr, dtype=np.float32)
    assert D32.dtype == np.float32 and np.allclose(D32, trace_distances(tr), rtol=1e-6)


@pytest.mark.parametrize("pad", ["append", "prepend"])
def test_cross_distances_are_blocks_of_the_full_matrix(pad):
    tr = traces(30, seed=3)
    D = trace_distances(tr, pad=pad)
    np.testing.assert_allclose(trace_cross_distances(tr[:7], tr[5:], pad=pad), D[:7, 5:], atol=1e-12)
    P = PreparedTraces(tr, pad=pad)
    np.testing.assert_allclose(P.distances_to(np.array([4, 9])), D[:, [4, 9]], atol=1e-12)
    np.testing.assert_allclose(
        P.subset(np.array([1, 2, 3])).distances_to(np.array([0])), D[[1, 2, 3]][:, [1]], atol=1e-12
    )


def test_edit_cross_and_incremental_update():
    rng = np.random.default_rng(4)
    seqs = [list(rng.integers(0, 4, rng.integers(0, 8))) for _ in range(25)]
    D = trace_distances(seqs, "edit", substitution_cost=2)
    assert D[3, 7] == naive_edit(seqs[3], seqs[7], 2)
    new = list(seqs)
    new[2], new[11] = [0, 0, 1], [3]
    D2 = update_trace_distances(D.copy(), new, [2, 11], "edit", substitution_cost=2)
    np.testing.assert_array_equal(D2, trace_distances(new, "edit", substitution_cost=2))


def test_continuous_incremental_update_equals_full_recompute():
    tr = traces(35, seed=5)
    D = trace_distances(tr)
    tr2 = list(tr)
    tr2[0], tr2[20] = np.ones((3, 2)), np.zeros((0, 2))
    np.testing.assert_allclose(update_trace_distances(D.copy(), tr2, [20, 0]), trace_distances(tr2), atol=1e-12)


def test_dtw_matches_reference_and_is_not_a_metric():
    tr = traces(12, seed=6)
    D = trace_distances(tr, "dtw")
    for i, j in [(0, 1), (2, 5), (7, 11)]:
        assert D[i, j] == pytest.approx(K.dtw_numpy(tr[i], tr[j]))
    a, b, c = np.array([[0.0], [1.0]]), np.array([[0.0], [0.0], [1.0]]), np.array([[0.0], [0.0], [0.0], [1.0], [1.0]])
    # warping makes repeated steps free: DTW(a, b) = 0 although a != b - not a metric
    assert trace_distances([a, b, c], "dtw")[0, 1] == 0.0


@pytest.mark.parametrize("method", ["full", "topk"])
def test_out_of_sample_of_embedded_points_gives_their_coordinates(method):
    rng = np.random.default_rng(7)
    X = rng.normal(size=(700, 3))
    D = cdist(X, X)
    res = classical_mds(D, 3, method=method)
    np.testing.assert_allclose(res.model.transform(D), res.coordinates, atol=1e-8)
    y = rng.normal(size=(5, 3))
    placed = res.model.transform(cdist(y, X))
    both = np.vstack([res.coordinates, placed])
    assert procrustes_error(np.vstack([X, y]), both) < 1e-12  # new points land where they belong


def test_float32_in_place_mds_matches_float64():
    rng = np.random.default_rng(8)
    X = rng.normal(size=(800, 2))
    D = cdist(X, X)
    a = classical_mds(D, 2, method="topk").coordinates
    D32 = D.astype(np.float32)
    b = classical_mds(D32, 2, method="topk", overwrite=True).coordinates
    assert procrustes_error(a, b) < 1e-10
    assert not np.allclose(D32, D.astype(np.float32))  # the input really was reused as K


def test_landmark_mds_is_exact_on_euclidean_data_and_close_on_traces():
    rng = np.random.default_rng(9)
    X = rng.normal(size=(2000, 2))
    res = landmark_mds(2000, lambda idx: cdist(X, X[idx]), 2, n_landmarks=50)
    assert res.landmarks.size == 50 and procrustes_error(X, res.coordinates) < 1e-20
    from sensorimotor.tools.bench.embedding import continuous_traces

    tr, P = continuous_traces(3000, seed=2)
    exact = classical_mds(trace_distances(tr, dtype=np.float32), 2, method="topk", overwrite=True).coordinates
    lm = landmark_trace_embedding(tr, 2, n_landmarks=200, seed=0)
    assert procrustes_error(exact, lm.coordinates) < 5e-3
    again = landmark_trace_embedding(tr, 2, n_landmarks=200, seed=0)
    assert again.coordinates.tobytes() == lm.coordinates.tobytes()


def test_landmark_model_places_new_traces():
    from sensorimotor.tools.bench.embedding import continuous_traces

    tr, P = continuous_traces(1500, seed=3)
    lm = landmark_trace_embedding(tr[:1000], 2, n_landmarks=150)
    new = lm.model.transform(trace_cross_distances(tr[1000:], [tr[i] for i in lm.landmarks]))
    assert procrustes_error(P, np.vstack([lm.coordinates, new])) < 0.01
