"""The acceptance rules of the generic program (agent/programs/acceptance.py), without a world."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sensorimotor.agent.programs.acceptance import (
    Score,
    compare,
    compare_ends,
    end_disparity,
    noise,
    sweep_score,
)


def test_a_sweep_is_scored_by_goals_and_the_length_of_the_traces_that_reach_it():
    s = sweep_score([True, False, True], [[0, 1], [0], [1, 1, 1, 1]])
    assert s == Score(2 / 3, 3.0, 3)
    assert sweep_score([False], [[0]]).length == math.inf


def test_deterministic_more_goals_or_shorter_is_better_and_the_same_is_equal():
    acc = Score(0.8, 10.0, 20)
    assert compare(Score(0.9, 30.0, 20), acc, False).better
    assert compare(Score(0.8, 9.0, 20), acc, False).better
    v = compare(Score(0.8, 10.0, 20), acc, False)
    assert not v.better and v.equal
    v = compare(Score(0.7, 5.0, 20), acc, False)
    assert not v.better and not v.equal
    assert compare(Score(0.0, math.inf, 20), None, False).better


def test_stochastic_better_only_beyond_the_noise_of_both_estimates():
    acc = Score(0.70, 20.0, 88)
    margin = noise(Score(0.75, 20.0, 88), acc)
    assert 0.1 < margin < 0.13  # 1.64 standard errors of two fractions from 88 traces each
    v = compare(Score(0.75, 20.0, 88), acc, True)
    assert not v.better and v.equal  # within the noise: as good
    assert compare(Score(0.70 + margin + 0.01, 20.0, 88), acc, True).better
    assert compare(Score(0.72, 15.0, 88), acc, True).better  # as good, a fifth shorter
    v = compare(Score(0.70 - margin - 0.01, 20.0, 88), acc, True)
    assert not v.better and not v.equal
    # more traces, less noise: the same gain is beyond it
    assert compare(Score(0.75, 20.0, 4000), Score(0.70, 20.0, 4000), True).better


@pytest.mark.parametrize("good", [True, False])
def test_net_moves_are_ranked_by_where_their_traces_end(good):
    v = compare_ends(0.01, 0.02, good)
    assert v.better == good and not v.equal
    assert compare_ends(0.02, 0.02, good).equal == good


def test_end_disparity_is_zero_when_displacements_match_the_starts():
    starts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    goal = np.array([0.5, 0.5])
    at_goal = {i: (s, goal.copy()) for i, s in enumerate(starts)}
    assert end_disparity(at_goal) == pytest.approx(0.0, abs=1e-12)
    same_way = {i: (s, s + 1.0) for i, s in enumerate(starts)}
    assert end_disparity(same_way) == 1.0
    assert end_disparity({0: (starts[0], goal), 1: (starts[1], goal)}) is None
