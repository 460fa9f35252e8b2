"""The rules by which the generic program fits box actions to a body (`agent.programs.box_moves`):
net moves where the moves add up, half moves where the body follows them more faithfully."""

from __future__ import annotations

import numpy as np

from sensorimotor.agent.programs.box_moves import move_scale, moves_add_up, probe_half_moves, unexplained

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
