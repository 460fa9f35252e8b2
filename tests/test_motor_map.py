"""Motor coordinates fitted from frames and the moves sent (agent.learners.motor_map)."""

from __future__ import annotations

import numpy as np
import pytest

from sensorimotor.agent.embedding import procrustes_error
from sensorimotor.agent.learners.motor_map import MotorMap, fit_motor_map

SIDE = 16


def blob(p: np.ndarray) -> np.ndarray:
    """A 16 x 16 frame of a Gaussian spot at position p in [0, 1]^2 (a nonlinear sensor)."""
    g = (np.arange(SIDE) + 0.5) / SIDE
    yy, xx = np.meshgrid(g, g, indexing="ij")
    return np.exp(-((xx - p[0]) ** 2 + (yy - p[1]) ** 2) / (2 * 0.15**2)).reshape(-1)


def random_moves(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random moves of the spot by 0.04 x the action (actions in [-1, 1]^2), kept inside the frame."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(0.2, 0.8, 2)
    before, acts, after = [], [], []
    for _ in range(n):
        a = rng.uniform(-1, 1, 2)
        q = np.clip(p + 0.04 * a, 0.15, 0.85)
        a = (q - p) / 0.04  # the move made (clipped at the edge)
        before.append(blob(p))
        acts.append(a)
        after.append(blob(q))
        p = q if rng.random() > 0.02 else rng.uniform(0.2, 0.8, 2)
    return np.array(before), np.array(acts), np.array(after)


def test_motor_coordinates_of_a_spot_are_its_position_in_units_of_the_moves():
    before, acts, after = random_moves(3000, seed=0)
    m = fit_motor_map(before, acts, after, components=16, seed=0)
    g = np.linspace(0.25, 0.75, 6)
    grid = np.array([(x, y) for x in g for y in g])
    z = m(np.array([blob(p) for p in grid]))
    assert procrustes_error(grid, z) < 0.02
    # one move of the spot is the action sent, in the map's coordinates (units of the command)
    step = m(blob(np.array([0.5, 0.5]) + 0.04 * np.array([1.0, 0.0]))) - m(blob(np.array([0.5, 0.5])))
    assert np.allclose(step, [1.0, 0.0], atol=0.15), step
    # deterministic given the seed; and its state round-trips
    again = fit_motor_map(before, acts, after, components=16, seed=0)
    assert np.array_equal(again(before[:5]), m(before[:5]))
    assert np.array_equal(MotorMap.from_state(m.state())(before[:5]), m(before[:5]))


def test_principal_components_alone_are_a_worse_state_than_the_motor_map():
    """The reason the map exists: PCA of the frames bends the square (the peer the zoo reports)."""
    before, acts, after = random_moves(3000, seed=1)
    m = fit_motor_map(before, acts, after, components=16, seed=0)
    g = np.linspace(0.25, 0.75, 6)
    grid = np.array([(x, y) for x in g for y in g])
    frames = np.array([blob(p) for p in grid])
    c = frames - frames.mean(axis=0)
    pca = c @ np.linalg.svd(c, full_matrices=False)[2][:2].T
    assert procrustes_error(grid, m(frames)) < 0.5 * procrustes_error(grid, pca)


def test_transitions_that_disagree_are_refused():
    before, acts, after = random_moves(50, seed=2)
    with pytest.raises(ValueError, match="disagree"):
        fit_motor_map(before, acts[:-1], after)
    with pytest.raises(ValueError, match="disagree"):
        fit_motor_map(before, acts, after[:, :-1])
    with pytest.raises(ValueError, match="too few"):
        fit_motor_map(before[:1, :1], acts[:1], after[:1, :1])
