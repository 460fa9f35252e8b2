"""The rules by which the generic program fits box actions to a body (`agent.programs.box_moves`):
net moves where the moves add up, half moves where the body follows them more faithfully, and each
move axis's gain where the body carries its axes out unevenly."""

from __future__ import annotations

import numpy as np

from sensorimotor.agent.programs.box_moves import (
    axis_gains,
    move_scale,
    moves_add_up,
    probe_half_moves,
    spill,
    spill_scale,
    unexplained,
)

TABLE = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], dtype=np.float64)


def _speed_limited_steps(scale: float, seed: int, n: int = 500) -> tuple[np.ndarray, np.ndarray]:
    """A hand commanded by increments (its target moves 0.05 x the move) that moves toward its
    target at most 0.025 per axis and step, as a lagging arm: a whole move spills into the next
    steps, a half move is carried out at once. Random moves; (moves sent, displacements)."""
    rng = np.random.default_rng(seed)
    x, target = np.zeros(3), np.zeros(3)
    moves, steps = [], []
    for _ in range(n):
        a = scale * TABLE[rng.integers(len(TABLE))]
        target = target + 0.05 * a
        y = x + np.clip(target - x, -0.025, 0.025)
        moves.append(a)
        steps.append(y - x)
        x = y
    return np.array(moves), np.array(steps)


def test_a_lagging_hand_takes_half_moves_and_an_exact_one_keeps_whole_moves():
    for seed in (0, 1, 2):
        whole = unexplained(*_speed_limited_steps(1.0, seed))
        half = unexplained(*_speed_limited_steps(0.5, seed))
        assert whole is not None and half is not None
        assert whole > 0.3 and half < 1e-9, (whole, half)
        assert probe_half_moves(whole) and move_scale(whole, half) == 0.5
    rng = np.random.default_rng(3)
    a = TABLE[rng.integers(len(TABLE), size=400)]
    exact = unexplained(a, 0.05 * a + 1e-4 * rng.standard_normal(a.shape))
    assert exact is not None and exact < 0.01
    assert not probe_half_moves(exact) and move_scale(exact, None) == 1.0
    assert unexplained(a[:5], a[:5]) is None  # too few steps to tell
    assert move_scale(0.5, 0.45) == 1.0  # half moves no better by a tenth of a step: whole moves


def test_moves_add_up_for_a_hand_and_not_for_a_car_pushed_up_a_hill():
    rng = np.random.default_rng(0)
    starts = rng.uniform(-1, 1, size=(40, 2))
    # a hand: each trace's moves sum to its way to the goal at 0, up to where in the goal region it stopped
    nets = -starts / 0.05 + rng.normal(0, 0.5, size=starts.shape)
    ends = starts + 0.05 * nets
    assert moves_add_up(nets, ends - starts) is True
    # a car: the summed force says little of where (position, velocity) a trace went
    force = rng.choice([-1.0, 1.0], size=(40, 60))
    car_ends = []
    for (p, v), f in zip(starts, force, strict=True):
        for u in f:
            v = np.clip(v + 0.001 * u - 0.0025 * np.cos(3 * p), -0.07, 0.07)
            p = np.clip(p + v, -1.2, 0.6)
        car_ends.append((p, v))
    assert moves_add_up(force.sum(axis=1, keepdims=True), np.array(car_ends) - starts) is False
    assert moves_add_up(nets[:3], (ends - starts)[:3]) is None


def test_over_noisy_coordinates_a_lagging_hand_spills_and_an_exact_one_does_not():
    """Camera frames' motor coordinates carry the map's own error. With noise of 0.03 on every step
    (more than half a half move's step), the share a fit leaves unexplained reads even an exact
    body as unfaithful, while the spill into the next step (a coefficient, which noise does not
    bias) tells the lagging body from the exact one and whole moves from half ones."""
    rng = np.random.default_rng(5)
    got = {}
    for lag in (True, False):
        for scale in (1.0, 0.5):
            moves, steps = _speed_limited_steps(scale, 7, n=1500) if lag else _exact_steps(scale, 7, 1500)
            noisy = steps + 0.03 * rng.standard_normal(steps.shape)
            previous = np.vstack([np.zeros((1, 3)), moves[:-1]])
            got[lag, scale] = (spill(moves[1:], previous[1:], noisy[1:]), unexplained(moves, noisy))
    (lag_w, _), (lag_h, _) = got[True, 1.0], got[True, 0.5]
    (ex_w, ex_wu), (ex_h, ex_hu) = got[False, 1.0], got[False, 0.5]
    assert probe_half_moves(ex_wu) and ex_hu > ex_wu, got  # unexplained: the noise, not the body
    assert lag_w > 0.3 and lag_h < 0.1 and ex_w < 0.05 and ex_h < 0.1, got  # spill: the lag alone
    assert spill_scale(lag_w, lag_h) == 0.5 and spill_scale(ex_w, ex_h) == 1.0


def _exact_steps(scale: float, seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    moves = scale * TABLE[rng.integers(len(TABLE), size=n)]
    return moves, 0.05 * moves


def test_spill_needs_enough_rows():
    m = TABLE[:5]
    assert spill(m, m, 0.05 * m) is None


def _hand_sweep(gains: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sweep of a hand whose axes carry out a move at `gains` x 0.05: starts on a 4 x 4 x 4
    lattice, each trace's summed moves bring it into a goal region of radius 0.05 round 0 (the
    moves' units are whole steps). Returns (starts, net moves, displacements)."""
    rng = np.random.default_rng(seed)
    axis = np.linspace(-0.15, 0.15, 4)
    starts = np.array([[x, y, z] for x in axis for y in axis for z in axis])
    stop = rng.uniform(-0.03, 0.03, size=starts.shape)  # where in the goal region it stopped
    nets = np.rint((stop - starts) / (0.05 * gains))
    return starts, nets, 0.05 * gains * nets


def test_axis_gains_put_a_net_move_in_the_units_the_body_senses():
    from scipy.spatial import procrustes

    uneven = np.array([0.7, 1.0, 1.0])  # one axis carried out at 70 % of the others' gain
    for seed in (0, 1, 2):
        starts, nets, moved = _hand_sweep(uneven, seed)
        gains = axis_gains(nets, moved)
        assert gains is not None
        assert np.allclose(gains, uneven / uneven.mean(), atol=0.02), gains
        before = procrustes(starts, nets)[2]
        after = procrustes(starts, nets * gains)[2]
        floor = procrustes(starts, moved)[2]  # the sensed displacements themselves: where each trace stopped
        assert after < 0.7 * before and after < 1.1 * floor, (before, after, floor)  # the stretch is mended
    # a reversed motor: the axis runs against its moves, and has the magnitude of its gain
    starts, nets, moved = _hand_sweep(uneven, 0)
    flipped = moved * np.array([-1.0, 1.0, 1.0])
    gains = axis_gains(nets, flipped)
    assert gains is not None and np.allclose(gains, uneven / uneven.mean(), atol=0.02), gains
    assert procrustes(starts, nets * gains)[2] < 0.7 * procrustes(starts, nets)[2]
    starts, nets, moved = _hand_sweep(np.ones(3), 0)
    even = axis_gains(nets, moved)
    assert even is not None and np.allclose(even, 1.0, atol=0.02)


def test_axis_gains_refuse_what_is_not_one_gain_per_axis():
    starts, nets, moved = _hand_sweep(np.array([0.7, 1.0, 1.0]), 0)
    turn = np.array([[np.cos(0.6), np.sin(0.6), 0.0], [-np.sin(0.6), np.cos(0.6), 0.0], [0.0, 0.0, 1.0]])
    assert axis_gains(nets, moved @ turn) is None  # the sensed axes are not the move axes
    still = moved.copy()
    still[:, 0] = 0.0
    assert axis_gains(nets, still) is None  # an axis that does not move
    rng = np.random.default_rng(0)
    assert axis_gains(nets, rng.normal(size=moved.shape)) is None  # moves that do not add up
    assert axis_gains(nets, moved[:, :2]) is None  # not one displacement per move axis
    assert axis_gains(nets[:3], moved[:3]) is None  # too few traces to tell
