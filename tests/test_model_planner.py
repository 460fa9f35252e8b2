"""The model-based planner (agent/learners/model_planner.py): interpolation, the learned model, and
a point mass in a square that it learns to steer to a small goal with canonical traces."""

from __future__ import annotations

import itertools

import numpy as np

from sensorimotor.agent.learners.model_planner import ModelPlanner, interpolation, node_of, node_points, plan_job

ACTIONS = np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=2)))
GOAL = np.array([0.5, 0.5])


def test_interpolation_reproduces_linear_functions_and_weights_sum_to_one():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1, (50, 3))
    idx, w = interpolation(pts, 5)
    nodes = node_points(5, 3)
    assert np.allclose(w.sum(axis=1), 1.0)
    f = nodes @ np.array([1.0, -2.0, 0.5])
    assert np.allclose((w * f[idx]).sum(axis=1), pts @ np.array([1.0, -2.0, 0.5]))
    assert node_of(np.array([0.0, 0.0, 0.0]), 5) == 0 and node_of(np.array([1.0, 1.0, 1.0]), 5) == 124


def _point_mass(planner: ModelPlanner, steps: int, seed: int) -> None:
    """Learn in a unit square: x' = x + 0.04 a (clipped), goal within 0.06 of the centre, 40-step episodes."""
    rng = np.random.default_rng(seed)
    x, t = rng.uniform(0.1, 0.9, 2), 0
    for k in range(steps):
        a = planner.act(x)
        x2 = np.clip(x + 0.04 * ACTIONS[a], 0.0, 1.0)
        goal = bool(np.linalg.norm(x2 - GOAL) < 0.06)
        planner.observe(x, a, x2, "goal" if goal else "continue")
        x, t = x2, t + 1
        if goal or t >= 40:
            x, t = rng.uniform(0.1, 0.9, 2), 0
        if k % 100 == 99:
            planner.install(plan_job(**planner.job_args()))


def _greedy(planner: ModelPlanner, x: np.ndarray) -> list[int]:
    trace = []
    w = planner.w
    for _ in range(40):
        a = int(np.argmax(planner.q(x, w)))
        trace.append(a)
        x = np.clip(x + 0.04 * ACTIONS[a], 0.0, 1.0)
        if np.linalg.norm(x - GOAL) < 0.06:
            return trace
    return trace + [-1]


def test_planner_steers_a_point_mass_to_a_small_goal_from_every_start():
    planner = ModelPlanner(2, ACTIONS, discrete=False, grid=21, seed=0)
    _point_mass(planner, 3000, seed=0)
    assert planner.goals.sum() > 0
    starts = [np.array(p) for p in itertools.product((0.2, 0.4, 0.6, 0.8), repeat=2)]
    traces = [_greedy(planner, s) for s in starts]
    assert all(t[-1] != -1 for t in traces)  # every start reaches the goal
    # shortest paths: from (0.2, 0.2) the centre is 0.3 away on each axis, 0.04 a step, so about 6
    # diagonal steps; never more than a few extra
    lengths = [len(t) for t in traces]
    assert max(lengths) <= 9, lengths
    # the first move from a corner start points at the goal on both axes
    assert ACTIONS[traces[0][0]].tolist() == [1.0, 1.0] and ACTIONS[traces[-1][0]].tolist() == [-1.0, -1.0]


def test_planner_state_round_trips():
    planner = ModelPlanner(2, ACTIONS, discrete=False, grid=9, seed=3)
    _point_mass(planner, 300, seed=1)
    copy = ModelPlanner(2, ACTIONS, discrete=False, grid=9, seed=99)
    copy.restore(planner.state())
    x = np.array([0.3, 0.7])
    assert np.array_equal(copy.q(x), planner.q(x)) and copy.act(x) == planner.act(x)
