"""Chapter 8 building blocks: the dynamics, Sarsa(lambda) with tile coding on the true state, and
the Kalman velocity estimate."""

import math

import numpy as np
import pytest

from sensorimotor.agent.learners.kalman_velocity import VelocityFilter
from sensorimotor.agent.learners.sarsa_lambda import SarsaLambda, TileCoder
from sensorimotor.worlds.mountaincar_dynamics import MountainCarParams, random_state, step


def test_dynamics_follow_equations_8_1_to_8_6():
    x, v = 0.3, 0.01
    x2, v2, done = step(x, v, 1)
    expect_v = v + 0.001 + 0.0025 * math.cos(math.pi / 4 * x + math.pi / 2)
    assert v2 == pytest.approx(expect_v) and x2 == pytest.approx(x + expect_v) and not done
    assert step(0.0, 0.07, 1)[1] == pytest.approx(0.07)  # velocity clipped at v_max
    assert step(-1.99, -0.05, -1)[:2] == (-2.0, 0.0)  # the left wall stops the car
    assert step(1.88, 0.05, 1)[2]  # x > 1.9 is the goal
    with pytest.raises(ValueError):
        step(0.0, 0.0, 2)


def test_full_throttle_alone_cannot_climb_out_of_the_valley():
    x, v = -0.0, 0.0  # the valley bottom is where the slope term vanishes
    for _ in range(2000):
        x, v, done = step(x, v, 1)
        assert not done


def steps_to_goal(agent, rng, starts=20, cap=2000):
    total = 0
    for _ in range(starts):
        x, v = random_state(rng)
        for t in range(cap):  # noqa: B007 (t counts the steps taken, read after the loop)
            x, v, done = step(x, v, agent.act(np.array([x, v])) - 1)
            if done:
                break
        total += t + 1
    return total / starts


def test_sarsa_lambda_with_tiles_solves_mountain_car_on_the_true_state():
    prm = MountainCarParams()
    coder = TileCoder([prm.x_min, -prm.v_max], [prm.x_max, prm.v_max], tiles=10, n_tilings=8)
    agent = SarsaLambda(coder, 3, alpha=0.3, gamma=0.99, lam=0.9, epsilon=0.0, seed=0)
    rng = np.random.default_rng(0)
    before = steps_to_goal(agent, np.random.default_rng(1), starts=10)
    for _ in range(150):
        x, v = random_state(rng)
        agent.begin_episode()
        a = agent.act(np.array([x, v]))
        for _ in range(3000):
            x2, v2, done = step(x, v, a - 1)
            if done:
                agent.learn_one(np.array([x, v]), a, -1.0, np.array([x2, v2]), None)
                break
            a2 = agent.act(np.array([x2, v2]))
            agent.learn_one(np.array([x, v]), a, -1.0, np.array([x2, v2]), a2)
            x, v, a = x2, v2, a2
    after = steps_to_goal(agent, np.random.default_rng(1), starts=10)
    assert after < 0.5 * before and after < 400, (before, after)


def test_tile_coder_activates_one_tile_per_tiling():
    c = TileCoder([0.0, 0.0], [1.0, 1.0], tiles=4, n_tilings=3)
    a = c.active(np.array([0.5, 0.5]))
    assert a.size == 3 and len(set(a // c.per_tiling)) == 3 and a.max() < c.size
    assert not np.array_equal(c.active(np.array([0.1, 0.1])), c.active(np.array([0.9, 0.9])))


def test_kalman_velocity_beats_finite_differences():
    rng = np.random.default_rng(0)
    prm = MountainCarParams()
    x, v = -0.5, 0.0
    xs, vs = [], []
    for t in range(600):
        x, v, _ = step(x, v, 1 if (t // 60) % 2 else -1, prm)
        xs.append(x)
        vs.append(v)
    noisy = np.array(xs) + rng.normal(0.0, 0.01, len(xs))
    f = VelocityFilter(measurement_var=1e-4)
    f.reset(noisy[0])
    est = np.array([f.update(z)[1] for z in noisy])
    fd = np.diff(noisy, prepend=noisy[0])
    rmse_kf = np.sqrt(np.mean((est[50:] - np.array(vs)[50:]) ** 2))
    rmse_fd = np.sqrt(np.mean((fd[50:] - np.array(vs)[50:]) ** 2))
    assert rmse_kf < 0.4 * rmse_fd, (rmse_kf, rmse_fd)


def test_kalman_velocity_matches_filterpys_filter():
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import KalmanFilter

    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.F, kf.H = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    kf.R, kf.Q = np.array([[1e-4]]), Q_discrete_white_noise(2, 1.0, 1e-5)
    kf.P, kf.x = np.diag([1e-4, 1.0]), np.array([[0.3], [0.0]])
    f = VelocityFilter(measurement_var=1e-4)
    f.reset(0.3)
    for z in np.random.default_rng(0).normal(0.3, 0.05, 200):
        kf.predict()
        kf.update(np.array([[z]]))
        assert f.update(z) == pytest.approx((kf.x[0, 0], kf.x[1, 0]), rel=1e-9, abs=1e-12)
    f2 = VelocityFilter(measurement_var=1e-4)
    f2.restore(f.state())
    assert np.allclose(f2.state()["P"], kf.P) and f2.update(0.31) == f.update(0.31)


def test_window_velocity_follows_a_quantised_swing_with_less_lag_than_the_kalman_filter():
    """A position quantised to whole vergence steps, swinging as the car does in the valley: the
    window slope lags the true velocity by about window / 2 steps, the program's Kalman filter
    (measurement variance 1/12, process variance 1e-5, in vergence steps) by some 14."""
    from sensorimotor.agent.learners.window_velocity import WindowVelocity

    t = np.arange(600)
    w = 2 * np.pi / 120
    vel = 8 * w * np.cos(w * t)
    quantised = np.round(8 * np.sin(w * t))

    def lag_and_rmse(f):
        f.reset(quantised[0])
        est = np.array([f.update(z)[1] for z in quantised])
        lag = int(np.argmax([np.dot(est[120:], np.roll(vel, k)[120:]) for k in range(40)]))
        return lag, float(np.sqrt(np.mean((est[120:] - vel[120:]) ** 2)))

    lag_w, rmse_w = lag_and_rmse(WindowVelocity(8))
    lag_k, rmse_k = lag_and_rmse(VelocityFilter(measurement_var=1 / 12, process_var=1e-5))
    assert lag_w <= 5 and lag_k >= 10, (lag_w, lag_k)
    assert rmse_w < 0.5 * rmse_k, (rmse_w, rmse_k)


def test_window_velocity_is_the_least_squares_slope_and_restores():
    from sensorimotor.agent.learners.window_velocity import WindowVelocity

    f = WindowVelocity(3)
    f.reset(1.0)
    assert f.update(1.0) == (1.0, 0.0)
    f.update(2.0)
    assert f.update(4.0) == pytest.approx((4.0, np.polyfit(range(4), [1.0, 1.0, 2.0, 4.0], 1)[0]))
    assert f.update(5.0)[1] == pytest.approx(np.polyfit(range(4), [1.0, 2.0, 4.0, 5.0], 1)[0])
    g = WindowVelocity(3)
    g.restore(f.state())
    assert g.update(7.0) == f.update(7.0)
    with pytest.raises(ValueError, match="window"):
        WindowVelocity(0)
