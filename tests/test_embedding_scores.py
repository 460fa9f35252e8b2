"""The field's embedding scores (agent/embedding/scores.py): hand-computed small cases, sklearn's
trustworthiness on random cases, the bounded cost for large embeddings, and the link carrying them."""

import numpy as np
import pytest

from sensorimotor.agent.embedding.scores import (
    continuity,
    dissimilarity,
    field_scores,
    max_neighbours,
    subsample,
    trustworthiness,
)
from sensorimotor.agent.evaluation import embedding_scores
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.base import Decision, EmbeddingOutput, Program
from sensorimotor.protocol import codec
from sensorimotor.protocol.messages import ActionSpace, Embedding, Observation, SensorSpec, Trigger, Truth, WorldSpec

# Five points on a line at uneven gaps (no tied distances), and the map that swaps the two ends.
LINE = np.array([0.0, 1.0, 3.0, 6.0, 10.0])
SWAPPED = np.array([10.0, 1.0, 3.0, 6.0, 0.0])


def test_a_perfect_map_scores_perfectly():
    rng = np.random.default_rng(0)
    truth = np.stack(np.meshgrid(np.arange(5.0), np.arange(4.0)), -1).reshape(-1, 2)  # a grid: many ties
    rot = np.linalg.qr(rng.normal(size=(2, 2)))[0]
    emb = 3.0 * truth @ rot + 7.0
    s = field_scores(truth, emb)
    assert s is not None
    assert s.trustworthiness == pytest.approx(1.0) and s.continuity == pytest.approx(1.0)
    assert s.metric_dissimilarity == pytest.approx(0.0, abs=1e-12)
    assert s.topological_dissimilarity == pytest.approx(0.0, abs=1e-12)
    assert (s.n_neighbors, s.n_points) == (5, 20)
    # an affine (not similar) image is still perfect for Laflaquière's scores
    assert dissimilarity(truth, truth @ np.array([[2.0, 0.5], [0.0, 0.3]])) == pytest.approx(0.0, abs=1e-12)


def test_a_shuffled_map_matches_the_hand_computed_values():
    # k = 1. Nearest embedded neighbour of each point, and its rank among the true neighbours:
    # p0 -> p3 (rank 3), p1 -> p4 (rank 4), p2 -> p1 (1), p3 -> p2 (1), p4 -> p1 (3).
    # Excess over k: 2 + 3 + 0 + 0 + 2 = 7; T = 1 - 7 * 2 / (n k (2n - 3k - 1)) = 1 - 14 / 30.
    assert trustworthiness(LINE, SWAPPED, 1) == pytest.approx(8 / 15)
    # Continuity, the true nearest neighbour's rank in the embedding: p0 -> p1 (3), p1 -> p0 (4),
    # p2 -> p1 (1), p3 -> p2 (1), p4 -> p3 (3): again 7.
    assert continuity(LINE, SWAPPED, 1) == pytest.approx(8 / 15)
    # Dissimilarities: the least-squares line of SWAPPED on LINE has slope -34/66 = -17/33, so
    # fitted distances are 17/33 of the true ones. Pairs (0,1) (0,2) (0,3) (0,4) (1,2) (1,3) (1,4)
    # (2,3) (2,4) (3,4):
    d_true = np.array([1, 3, 6, 10, 2, 5, 9, 3, 7, 4], float)
    d_emb = np.array([9, 7, 4, 10, 2, 5, 1, 3, 3, 6], float)
    diff = np.abs(d_emb - 17 / 33 * d_true) / 10.0  # max embedded distance 10
    assert dissimilarity(LINE, SWAPPED, 0.0) == pytest.approx(diff.mean())
    # the topological weight exp(-10 d_fit / max d_fit) = exp(-d_true) here (max d_true = 10)
    assert dissimilarity(LINE, SWAPPED, 10.0) == pytest.approx((diff * np.exp(-d_true)).mean())
    s = field_scores(LINE, SWAPPED, n_neighbors=5)  # k lowered to 2 for 5 points (k < n / 2)
    assert s is not None and s.n_neighbors == 2 and s.trustworthiness < 1.0


def test_trustworthiness_and_continuity_equal_sklearn_on_random_cases():
    manifold = pytest.importorskip("sklearn.manifold")
    rng = np.random.default_rng(3)
    for _ in range(25):
        n = int(rng.integers(7, 60))
        k = int(rng.integers(1, (n - 1) // 2 + 1))
        truth = rng.normal(size=(n, int(rng.integers(1, 4))))
        emb = truth[:, :1] * rng.uniform(0.5, 3) + rng.normal(size=(n, 2)) * rng.uniform(0, 2)
        assert trustworthiness(truth, emb, k) == pytest.approx(manifold.trustworthiness(truth, emb, n_neighbors=k))
        assert continuity(truth, emb, k) == pytest.approx(manifold.trustworthiness(emb, truth, n_neighbors=k))


def test_large_embeddings_are_scored_on_a_fixed_subsample():
    rng = np.random.default_rng(1)
    truth = rng.uniform(size=(3000, 2))
    emb = truth + rng.normal(scale=0.01, size=truth.shape)
    rows = subsample(3000, 400)
    assert rows.size == 400 and np.all(np.diff(rows) > 0)
    np.testing.assert_array_equal(rows, subsample(3000, 400))  # deterministic
    s = field_scores(truth, emb, max_points=400)
    assert s is not None and s.n_points == 400
    assert s == field_scores(truth[rows], emb[rows], max_points=400)
    assert 0.9 < s.trustworthiness <= 1.0


def test_undefined_cases_give_none_or_a_clear_error():
    assert max_neighbours(2) == 0 and max_neighbours(3) == 1 and max_neighbours(100) == 5
    assert field_scores(np.zeros((2, 2)), np.ones((2, 2))) is None  # too few points
    assert field_scores(LINE, np.zeros(5)) is None  # every embedded point the same
    with pytest.raises(ValueError, match="n_neighbors"):
        trustworthiness(LINE, SWAPPED, 3)
    with pytest.raises(ValueError, match="same rows"):
        field_scores(LINE, SWAPPED[:4])
    with pytest.raises(ValueError, match="NaN"):
        field_scores(LINE, np.r_[SWAPPED[:4], np.nan])


SPEC = WorldSpec("w", "toy", (SensorSpec("x", "float32", (1,)),), ActionSpace(n=2), program="toy", n_starts=5)


class EmbedOnce(Program):
    """Publishes the swapped line as its embedding on the first step."""

    name = "toy"

    def act(self, obs):
        if obs.step == 0:
            self.emit(EmbeddingOutput(Trigger.PERIODIC, (0, 1, 2, 3, 4), SWAPPED.reshape(-1, 1), (1.0,), 0))
        return Decision((0.0,))


def test_the_link_publishes_the_scores_in_the_embedding_message():
    out: list = []
    truth = Truth("w", "start_states", {"positions": LINE.reshape(-1, 1)})
    link = WorldLink("a0", SPEC, EmbedOnce(SPEC), lambda ch, m: out.append((ch, m)))
    link.truth = truth
    link.answer(Observation("w", 0, 0, 0, {"x": np.zeros(1, np.float32)}, 0.0))
    (emb,) = [m for ch, m in out if ch == "embedding"]
    back = codec.decode(Embedding, codec.encode(emb))
    assert back.scores is not None and back.scores == emb.scores
    assert back.scores.n_neighbors == 2 and back.scores.n_points == 5
    assert back.scores.trustworthiness == pytest.approx(trustworthiness(LINE, SWAPPED, 2))
    assert back.procrustes_error is not None
    untruthful: list = []
    WorldLink("a0", SPEC, EmbedOnce(SPEC), lambda ch, m: untruthful.append((ch, m))).answer(
        Observation("w", 0, 0, 0, {"x": np.zeros(1, np.float32)}, 0.0)
    )
    (plain,) = [m for ch, m in untruthful if ch == "embedding"]
    assert plain.scores is None and plain.procrustes_error is None
    assert embedding_scores(EmbeddingOutput(Trigger.PERIODIC, (0, 9), np.zeros((2, 1)), (1.0,), 0), truth) is None


def test_sme_watch_shows_the_scores():
    from sensorimotor.protocol.messages import EmbeddingScores
    from sensorimotor.tools.common import embedding_dict, format_embedding

    e = Embedding("a0", "w", 3, "periodic", (0, 1, 2), np.zeros((3, 1)), (1.0,), 0.01)
    assert "T=" not in format_embedding(e) and embedding_dict(e)["scores"] is None
    s = EmbeddingScores(0.95, 0.9, 0.125, 0.0625, 1, 3)
    scored = Embedding("a0", "w", 3, "periodic", (0, 1, 2), np.zeros((3, 1)), (1.0,), 0.01, scores=s)
    assert "T=0.950 C=0.900 Dm=0.125 Dt=0.0625" in format_embedding(scored)
    assert embedding_dict(scored)["scores"] == {
        "trustworthiness": 0.95,
        "continuity": 0.9,
        "metric_dissimilarity": 0.125,
        "topological_dissimilarity": 0.0625,
        "n_neighbors": 1,
        "n_points": 3,
    }
