"""The moves distance and weighted MDS (agent.embedding.move_counts, weighted_mds): identities, and
the map of a room with a wall, where the edit distance + classical MDS bends the cells round it."""

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from sensorimotor.agent.embedding import classical_mds, procrustes_error, trace_distances
from sensorimotor.agent.embedding.move_counts import move_count_distances, move_counts
from sensorimotor.agent.embedding.weighted_mds import distance_weights, weighted_mds
from sensorimotor.agent.programs.generic_jobs import embed_job
from sensorimotor.tools.experiments.geodesic_ceiling import shortest_traces as ceiling_traces


def shortest_traces(rows: list[str]) -> tuple[np.ndarray, list[list[int]]]:
    """The free cells ('.') of a layout and each one's shortest way to the goal ('G'), as actions
    (geodesic_ceiling's breadth-first search from the goal: a deterministic optimal policy)."""
    free = {(x, y) for y, r in enumerate(rows) for x, c in enumerate(r) if c in ".G"}
    goal = next((x, y) for y, r in enumerate(rows) for x, c in enumerate(r) if c == "G")
    cells = sorted((c for c in free if c != goal), key=lambda c: (c[1], c[0]))
    return np.array(cells, dtype=np.float64), ceiling_traces(cells, free, goal)


#: SimpleCrossing S9N1's layout of seed 0: a corridor along the top joined to the room at its left end
CORRIDOR = ["#########", "#.......#", "#.#######", "#.......#", "#.......#", "#.......#", "#.......#", "#......G#"]
#: a LavaGap-like room: a wall down the middle with one gap
GAP = ["#######", "#..#..#", "#.....#", "#..#..#", "#..#..#", "#..#.G#", "#######"]


def test_equal_weights_are_sklearn_smacof():
    from sklearn.manifold import smacof

    rng = np.random.default_rng(0)
    D = cdist(rng.normal(size=(15, 3)), rng.normal(size=(15, 3)))
    D = (D + D.T) / 2
    np.fill_diagonal(D, 0)
    X0 = rng.normal(size=(15, 2))
    ours = weighted_mds(D, 2, power=0, init=X0, max_iter=20, eps=0).coordinates
    theirs = smacof(D, n_components=2, init=X0, n_init=1, max_iter=20, eps=0, normalized_stress=False)[0]
    np.testing.assert_allclose(ours, theirs, atol=1e-8)


@pytest.mark.parametrize("power", [0.0, 2.0])
def test_euclidean_input_is_recovered_and_stress_never_rises(power):
    X = np.random.default_rng(1).normal(size=(30, 2))
    res = weighted_mds(cdist(X, X), 2, power=power)
    assert procrustes_error(X, res.coordinates) < 1e-10
    assert res.stress <= res.initial_stress + 1e-15
    assert distance_weights(np.array([[0.0, 2.0], [2.0, 0.0]]), power)[0, 1] == pytest.approx(2.0**-power)


def test_weighted_mds_rejects_bad_input():
    with pytest.raises(ValueError, match="square"):
        weighted_mds(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="weights"):
        weighted_mds(np.zeros((3, 3)), weights=-np.ones((3, 3)))


def test_move_counts_are_the_net_move_of_monotone_traces():
    traces = [[0, 0, 1], [1, 0], [], [3, 2, 3]]
    C = move_counts(traces, 4, skip=[2])
    np.testing.assert_array_equal(C, [[2, 1, 0, 0], [1, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 2]])
    np.testing.assert_allclose(move_count_distances(traces, 4, skip=[2]), cdist(C, C))
    with pytest.raises(ValueError, match="outside"):
        move_counts([[5]], 4)


@pytest.mark.parametrize(("layout", "bound"), [(CORRIDOR, 0.15), (GAP, 0.05)], ids=["corridor", "gap"])
def test_moves_and_weighted_mds_keep_the_places_round_a_wall(layout, bound):
    """Edit distance + classical MDS: 0.38 and 0.25; moves: 0.21 and 0.10; weighted: 0.13 and 0.05."""
    cells, traces = shortest_traces(layout)
    edit = procrustes_error(cells, classical_mds(trace_distances(traces, kind="edit", substitution_cost=2)).coordinates)
    D = move_count_distances(traces, 4)
    moves = procrustes_error(cells, classical_mds(D).coordinates)
    weighted = procrustes_error(cells, weighted_mds(D).coordinates)
    assert edit > 0.2  # the map of the ways round the wall
    assert weighted < bound and weighted < moves < edit


def test_embed_job_auto_picks_moves_and_weighted_mds_for_one_trace_a_start():
    cells, traces = shortest_traces(CORRIDOR)
    per = [[t] for t in traces]
    auto = embed_job(per, None, 2, n_actions=4, discrete_distance="auto", embedding="auto")["coordinates"]
    np.testing.assert_allclose(auto, weighted_mds(move_count_distances(traces, 4)).coordinates)
    old = embed_job(per, None, 2, n_actions=4)["coordinates"]  # the defaults of the function: edit, classical
    np.testing.assert_allclose(
        old, classical_mds(trace_distances(traces, kind="edit", substitution_cost=2)).coordinates
    )
    # several samples a start (a stochastic world): the estimators' distances and classical MDS, as before
    two = [[t, t] for t in traces]
    reached = [[True, True] for _ in traces]
    kw = {"n_actions": 4, "estimator": "mean_trace", "reached": reached}
    np.testing.assert_allclose(
        embed_job(two, None, 2, discrete_distance="auto", embedding="auto", **kw)["coordinates"],
        embed_job(two, None, 2, **kw)["coordinates"],
    )
