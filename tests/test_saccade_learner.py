import numpy as np
import pytest

from sensorimotor.agent.learners.saccade import SaccadeLearner


def toy_retina(n=64, seed=0):
    """Fields on a line at known positions; a target at position p lights fields near it."""
    pos = np.linspace(-10, 10, n)

    def lit(p):
        return np.exp(-0.5 * ((pos - p) / 0.7) ** 2)

    def reward(p_after):
        return float(lit(p_after)[np.abs(pos) < 2].sum())  # fovea: fields near 0

    return pos, lit, reward


def test_basic_rule_only_moves_on_improvement_and_robust_tracks_average():
    L = SaccadeLearner(3, [-1.0], [1.0], alpha=0.5, rule="basic", seed=0)
    d = np.array([1.0, 0.0, 0.5])
    pi0 = L.pi.copy()
    L.learn_one(d, np.array([0.2]), 4.0)
    np.testing.assert_allclose(L.R, [2.0, 0.0, 1.0])  # R_k += d_k a (R - R_k)
    np.testing.assert_allclose(L.pi[0], pi0[0] + 0.5 * (0.2 - pi0[0]))
    np.testing.assert_allclose(L.pi[1], pi0[1])  # inactive field untouched
    L.learn_one(d, np.array([0.9]), 1.0)  # worse than R_0 = 2: basic rule keeps R_0 and pi_0
    assert L.R[0] == 2.0
    R = SaccadeLearner(3, [-1.0], [1.0], alpha=0.5, rule="robust", seed=0)
    R.learn_one(d, np.array([0.2]), 4.0)
    R.learn_one(d, np.array([0.9]), 1.0)
    assert R.R[0] == pytest.approx(2.0 + 0.5 * (1.0 - 2.0))  # Eq 4.7: always tracks


def test_greedy_is_activation_weighted_mean():
    L = SaccadeLearner(2, [-5.0, -5.0], [5.0, 5.0], seed=1)
    L.pi[:] = [[1.0, 2.0], [3.0, -2.0]]
    np.testing.assert_allclose(L.greedy(np.array([1.0, 3.0])), [2.5, -1.0])
    np.testing.assert_allclose(L.greedy(np.zeros(2)), [0.0, 0.0])


def test_learns_field_positions_on_a_toy_retina():
    pos, lit, reward = toy_retina()
    rng = np.random.default_rng(0)
    L = SaccadeLearner(pos.size, [-12.0], [12.0], alpha=0.5, noise_sd=1.0, seed=0, exploration="gaussian")
    for _ in range(4000):
        target = rng.uniform(-8, 8)
        d = lit(target)
        a = L.act(d)
        L.learn_one(d, a, reward(target - a[0]))
    seen = L.experience > 5
    err = np.abs(L.positions[seen, 0] - (-pos[seen])).mean()  # -pi_k: minus the saccade to centre field k
    assert err < 1.0
    greedy_err = np.mean([abs(t - L.greedy(lit(t))[0]) for t in np.linspace(-7, 7, 30)])
    assert greedy_err < 0.6


def test_reset_estimates_raises_exploration():
    L = SaccadeLearner(4, [-1.0], [1.0], seed=2)
    d = np.ones(4)
    for _ in range(50):
        L.learn_one(d, L.greedy(d), 1.0)
    base = L.greedy(d)
    calm = np.std([L.act(d)[0] - base[0] for _ in range(200)])
    L.reset_estimates()
    wild = np.std([L.act(d)[0] - base[0] for _ in range(200)])
    assert wild > 2 * calm and L.resets == 1


def test_seeded_and_validated():
    a = SaccadeLearner(5, [-1.0], [1.0], seed=3).act(np.ones(5))
    b = SaccadeLearner(5, [-1.0], [1.0], seed=3).act(np.ones(5))
    assert a.tobytes() == b.tobytes()
    with pytest.raises(ValueError):
        SaccadeLearner(5, [1.0], [-1.0])
    with pytest.raises(ValueError, match="rule"):
        SaccadeLearner(5, [-1.0], [1.0], rule="fancy")
    with pytest.raises(ValueError, match="expected delta"):
        SaccadeLearner(5, [-1.0], [1.0]).learn_one(np.ones(4), np.zeros(1), 1.0)


def test_share_credit_divides_a_large_saccade_among_its_fields():
    """credit="share": a saccade lighting more than the typical total activation A teaches each lit
    field A / total of the Eq 4.5 step; one no larger than typical teaches as Eq 4.5."""
    A = SaccadeLearner(4, [-1.0], [1.0], alpha=0.5, seed=0)
    S = SaccadeLearner(4, [-1.0], [1.0], alpha=0.5, seed=0, credit="share")
    spot = np.array([1.0, 0.0, 0.0, 0.0])
    for L in (A, S):
        L.learn_one(spot, np.array([0.5]), 2.0)  # the first saccade sets A = 1
    np.testing.assert_allclose(S.pi, A.pi)  # total 1 <= A: the same step
    assert S.a_ref == pytest.approx(1.0)
    blob = np.ones(4)  # total 4: A moves to 1.06, the step is 1.06 / 4 of Eq 4.5's
    pi0 = S.pi.copy()
    S.learn_one(blob, np.array([-0.5]), 10.0)
    f = (1.0 + 0.02 * 3.0) / 4.0
    np.testing.assert_allclose(S.pi, pi0 + 0.5 * f * (-0.5 - pi0))
    np.testing.assert_allclose(S.experience, [1.0 + f, f, f, f])  # credited activation
    snap = S.state()
    T = SaccadeLearner(4, [-1.0], [1.0], seed=5, credit="share")
    T.restore(snap)
    assert T.a_ref == S.a_ref
    with pytest.raises(ValueError, match="credit"):
        SaccadeLearner(4, [-1.0], [1.0], credit="fancy")
